//! Piecewise-linear transfer function: f64 twin of `glsl/include/transfer.glsl`
//! (stage `transfer_lookup`). Colour and extinction τ (per world unit) are interpolated
//! linearly in s between control points and clamped outside their range.

use crate::gpu_types::TfPoint;

/// Control points `[s, r, g, b, τ]`, sorted by s.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    points: Vec<[f64; 5]>,
}

impl TransferFunction {
    /// Wraps validated points (non-empty, s non-decreasing, finite, colour and τ ≥ 0).
    pub fn new(points: Vec<[f64; 5]>) -> Self {
        Self { points }
    }

    /// Reads `[[s, r, g, b, τ], ...]`; the error says what was expected.
    pub fn from_toml(value: &toml::Value) -> Result<Self, String> {
        let expected = "a non-empty array of [s, r, g, b, tau] with s non-decreasing, finite numbers, colour and tau >= 0";
        let rows = value.as_array().filter(|a| !a.is_empty()).ok_or(expected)?;
        let mut points = Vec::with_capacity(rows.len());
        for (i, row) in rows.iter().enumerate() {
            let row = row
                .as_array()
                .filter(|r| r.len() == 5)
                .ok_or_else(|| format!("{expected} (point {i} is not 5 numbers)"))?;
            let mut p = [0.0; 5];
            for (o, v) in p.iter_mut().zip(row) {
                *o = match v {
                    toml::Value::Float(f) => *f,
                    toml::Value::Integer(n) => *n as f64,
                    _ => return Err(format!("{expected} (point {i} has a non-number)")),
                };
            }
            if p.iter().any(|x| !x.is_finite()) || p[1..].iter().any(|&x| x < 0.0) {
                return Err(format!("{expected} (point {i})"));
            }
            if points.last().is_some_and(|q: &[f64; 5]| p[0] < q[0]) {
                return Err(format!(
                    "{expected} (point {i} has s < the previous point's)"
                ));
            }
            points.push(p);
        }
        Ok(Self { points })
    }

    /// The control points.
    pub fn points(&self) -> &[[f64; 5]] {
        &self.points
    }

    /// (rgb, τ) at scalar s.
    pub fn lookup(&self, s: f64) -> ([f64; 3], f64) {
        let p = &self.points;
        let at = |q: &[f64; 5]| ([q[1], q[2], q[3]], q[4]);
        if s <= p[0][0] {
            return at(&p[0]);
        }
        for i in 1..p.len() {
            if s < p[i][0] {
                let t = (s - p[i - 1][0]) / (p[i][0] - p[i - 1][0]);
                let m = |k: usize| p[i - 1][k] + t * (p[i][k] - p[i - 1][k]);
                return ([m(1), m(2), m(3)], m(4));
            }
        }
        at(&p[p.len() - 1])
    }

    /// GPU layout.
    pub fn to_gpu(&self) -> Vec<TfPoint> {
        self.points
            .iter()
            .map(|p| TfPoint {
                color_tau: [p[1] as f32, p[2] as f32, p[3] as f32, p[4] as f32],
                s: p[0] as f32,
                _pad: [0.0; 3],
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_clamps() {
        let tf = TransferFunction::new(vec![[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.5, 0.0, 8.0]]);
        let (c, tau) = tf.lookup(0.25);
        assert!(
            (c[0] - 0.25).abs() < 1e-15
                && (c[1] - 0.125).abs() < 1e-15
                && (tau - 2.0).abs() < 1e-15
        );
        assert_eq!(tf.lookup(-3.0), ([0.0; 3], 0.0));
        assert_eq!(tf.lookup(7.0), ([1.0, 0.5, 0.0], 8.0));
    }
}
