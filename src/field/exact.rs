//! The generator's analytic field (`reconstruction.method = "exact"`): the Marschner–Lobb
//! function, evaluated where a reconstruction would be, so that images of generated data can be
//! compared with their truth. Renderers reach the generator only through this module.

use crate::data::marschner_lobb;
use crate::recon::mls::MlsValue;

/// Stage `exact_evaluate`: the generator's function at `x` relative to the generated grid,
/// whose first sample (at `origin`) is the function's (-1, -1, -1) — as the GPU twin computes
/// it, wherever the grid was placed.
pub fn exact_evaluate(origin: [f64; 3], x: [f64; 3]) -> MlsValue {
    let [wx, wy, wz] = std::array::from_fn(|a| x[a] - origin[a] - 1.0);
    MlsValue {
        value: marschner_lobb::rho(wx, wy, wz),
        gradient: marschner_lobb::rho_gradient(wx, wy, wz),
        neighbours: 1,
        terms: 1,
    }
}

/// The analytic field's constants as shader macros (`ML_F_M`, `ML_ALPHA`): one copy of each
/// number, the generator's.
pub fn defines() -> [(String, String); 2] {
    [
        ("ML_F_M".into(), format!("{:?}", marschner_lobb::F_M)),
        ("ML_ALPHA".into(), format!("{:?}", marschner_lobb::ALPHA)),
    ]
}
