//! A brick as bytes, for the rank that reads the input to send each other rank its piece
//! (issue 30 §2, "rank 0 may read and scatter"): the kd tree, the whole field's frame (origin,
//! value range), the brick's samples with their supports and the domain, its counts and, for
//! the Gaussian sum, its kernel volumes. Little-endian, versioned by a magic; a malformed or
//! truncated message is an error naming what was expected, never a panic.

use super::kd::{KdNode, KdTree};
use super::{Aabb, BrickError, GhostCount};
use crate::data::dataset::Location;
use crate::data::{Storage, Values};
use crate::field::SupportExtent;
use crate::recon::gaussian::KernelVolumes;
use crate::samples::mesh::Hull;
use crate::samples::{Domain, Positions, Provenance, SampleSet, Supports};
use glam::DVec3;

const MAGIC: &[u8; 8] = b"VMLSBRK2";

/// What one rank needs of the decomposition to render its brick.
#[derive(Debug, Clone, PartialEq)]
pub struct BrickMessage {
    pub tree: KdTree,
    pub rank: usize,
    /// The whole field's frame origin (world) and value range.
    pub frame_origin: [f64; 3],
    pub range: (f64, f64),
    /// The whole field's supports (splatting's sheets and ring are the undivided frame's).
    pub extent: SupportExtent,
    pub samples: SampleSet,
    pub count: GhostCount,
    pub volumes: Option<KernelVolumes>,
}

/// The strings a sample set's provenance can hold (`&'static str` there).
const KINDS: [&str; 11] = [
    "regular grid",
    "rectilinear grid",
    "curvilinear grid",
    "unstructured mesh",
    "scattered points",
    "uniform",
    "diagonal",
    "anisotropic-edges",
    "anisotropic-one-ring",
    "isotropic",
    "anisotropic",
];

struct Writer(Vec<u8>);

impl Writer {
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64s(&mut self, v: &[f64]) {
        v.iter().for_each(|&x| self.f64(x));
    }
    fn string(&mut self, s: &str) {
        self.u64(s.len() as u64);
        self.0.extend_from_slice(s.as_bytes());
    }
}

/// The message as bytes.
pub fn encode(m: &BrickMessage) -> Vec<u8> {
    let mut w = Writer(MAGIC.to_vec());
    w.u64(m.rank as u64);
    w.u64(m.tree.nodes.len() as u64);
    for n in &m.tree.nodes {
        match *n {
            KdNode::Leaf { rank } => {
                w.u64(0);
                w.u64(rank as u64);
            }
            KdNode::Split {
                axis,
                plane,
                below,
                above,
            } => {
                w.u64(1);
                w.u64(axis as u64);
                w.f64(plane);
                w.u64(below as u64);
                w.u64(above as u64);
            }
        }
    }
    w.u64(m.tree.boxes.len() as u64);
    for (lo, hi) in &m.tree.boxes {
        w.f64s(lo);
        w.f64s(hi);
    }
    w.f64s(&m.frame_origin);
    w.f64s(&[m.range.0, m.range.1]);
    let e = &m.extent;
    w.f64s(&e.support_box.0.to_array());
    w.f64s(&e.support_box.1.to_array());
    w.f64(e.thinnest);
    w.u64(e.radii.len() as u64);
    w.f64s(&e.radii);
    w.u64(m.count.own as u64);
    w.u64(m.count.ghosts as u64);
    let s = &m.samples;
    match &s.positions {
        Positions::Grid {
            dims,
            origin,
            spacing,
        } => {
            w.u64(0);
            dims.iter().for_each(|&d| w.u64(d as u64));
            w.f64s(origin);
            w.f64s(spacing);
        }
        Positions::Scattered(p) => {
            w.u64(1);
            w.u64(p.len() as u64);
            p.iter().for_each(|x| w.f64s(x));
        }
    }
    w.u64(match s.values.storage() {
        Storage::F32 => 0,
        Storage::U8 => 1,
        Storage::I8 => 2,
        Storage::U16 => 3,
        Storage::I16 => 4,
    });
    w.u64(s.values.len() as u64);
    match &s.values {
        Values::F32(v) => v
            .iter()
            .for_each(|x| w.0.extend_from_slice(&x.to_le_bytes())),
        Values::U8(v) => w.0.extend_from_slice(v),
        Values::I8(v) => v
            .iter()
            .for_each(|x| w.0.extend_from_slice(&x.to_le_bytes())),
        Values::U16(v) => v
            .iter()
            .for_each(|x| w.0.extend_from_slice(&x.to_le_bytes())),
        Values::I16(v) => v
            .iter()
            .for_each(|x| w.0.extend_from_slice(&x.to_le_bytes())),
    }
    match &s.supports {
        Supports::Uniform(h) => {
            w.u64(0);
            w.f64s(h);
        }
        Supports::PerSample(m) => {
            w.u64(1);
            w.u64(m.len() as u64);
            m.iter().for_each(|x| w.f64s(x));
        }
    }
    match &s.domain {
        Domain::Box { lo, hi } => {
            w.u64(0);
            w.f64s(lo);
            w.f64s(hi);
        }
        Domain::Hull(h) => {
            w.u64(1);
            w.u64(h.vertices.len() as u64);
            h.vertices.iter().for_each(|v| w.f64s(v));
            w.u64(h.triangles.len() as u64);
            for t in &h.triangles {
                t.iter().for_each(|&i| w.u64(u64::from(i)));
            }
        }
    }
    w.f64(s.spacing);
    let p = &s.provenance;
    w.string(p.kind);
    w.string(&p.array);
    w.u64(u64::from(p.location == Location::Cell));
    w.u64(p.merged as u64);
    w.u64(p.inverted_cells as u64);
    w.string(p.support_kind);
    match &m.volumes {
        None => w.u64(0),
        Some(KernelVolumes::Uniform(v)) => {
            w.u64(1);
            w.f64(*v);
        }
        Some(KernelVolumes::PerSample(v)) => {
            w.u64(2);
            w.u64(v.len() as u64);
            w.f64s(v);
        }
    }
    w.0
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], BrickError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(BrickError::Message(format!(
                "{what}: {n} bytes expected at byte {}, the message has {}",
                self.at,
                self.bytes.len()
            )));
        };
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u64(&mut self, what: &str) -> Result<u64, BrickError> {
        let b = self.take(8, what)?;
        Ok(u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
    }
    fn f64(&mut self, what: &str) -> Result<f64, BrickError> {
        let b = self.take(8, what)?;
        Ok(f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
    }
    fn f3(&mut self, what: &str) -> Result<[f64; 3], BrickError> {
        Ok([self.f64(what)?, self.f64(what)?, self.f64(what)?])
    }
    /// A count of items of `size` bytes each that the rest of the message can hold.
    fn count(&mut self, size: usize, what: &str) -> Result<usize, BrickError> {
        let n = self.u64(what)?;
        let left = (self.bytes.len() - self.at) as u64;
        if n.saturating_mul(size as u64) > left {
            return Err(BrickError::Message(format!(
                "{what}: {n} items of {size} bytes, but {left} bytes are left"
            )));
        }
        Ok(n as usize)
    }
    fn index(&mut self, below: usize, what: &str) -> Result<usize, BrickError> {
        let v = self.u64(what)?;
        if v as usize >= below || v > usize::MAX as u64 {
            return Err(BrickError::Message(format!(
                "{what}: {v}, expected below {below}"
            )));
        }
        Ok(v as usize)
    }
    fn kind(&mut self, what: &str) -> Result<&'static str, BrickError> {
        let n = self.count(1, what)?;
        let s = self.take(n, what)?;
        KINDS
            .iter()
            .find(|k| k.as_bytes() == s)
            .copied()
            .ok_or_else(|| BrickError::Message(format!("{what}: an unknown name")))
    }
    fn string(&mut self, what: &str) -> Result<String, BrickError> {
        let n = self.count(1, what)?;
        Ok(String::from_utf8_lossy(self.take(n, what)?).into_owned())
    }
}

/// A tree the decoder can walk: the root first, every split's children after it (so no walk
/// loops), its leaves each rank of `0..ranks` once, and `rank` one of them.
fn check_tree(nodes: &[KdNode], ranks: usize, rank: usize) -> Result<(), BrickError> {
    let bad = |what: &str| Err(BrickError::Message(format!("kd tree: {what}")));
    if nodes.is_empty() {
        return bad("no nodes");
    }
    let mut seen = vec![false; ranks];
    for (i, n) in nodes.iter().enumerate() {
        match *n {
            KdNode::Split { below, above, .. } if below <= i || above <= i => {
                return bad("a split whose child comes before it");
            }
            KdNode::Leaf { rank } if rank >= ranks || seen[rank] => {
                return bad("a rank twice, or beyond the boxes");
            }
            KdNode::Leaf { rank } => seen[rank] = true,
            KdNode::Split { .. } => {}
        }
    }
    if rank >= ranks || seen.iter().any(|s| !s) {
        return bad("not every rank has a leaf");
    }
    Ok(())
}

/// The message of `bytes`, checked.
pub fn decode(bytes: &[u8]) -> Result<BrickMessage, BrickError> {
    let mut r = Reader { bytes, at: 0 };
    if r.take(8, "magic")? != MAGIC {
        return Err(BrickError::Message("not a vmls brick message".into()));
    }
    let rank = r.u64("rank")? as usize;
    let nodes_len = r.count(16, "kd nodes")?;
    let mut nodes = Vec::with_capacity(nodes_len);
    for _ in 0..nodes_len {
        nodes.push(match r.u64("kd node tag")? {
            0 => KdNode::Leaf {
                rank: r.u64("leaf rank")? as usize,
            },
            1 => KdNode::Split {
                axis: r.index(3, "split axis")?,
                plane: r.f64("split plane")?,
                below: r.index(nodes_len, "node below")?,
                above: r.index(nodes_len, "node above")?,
            },
            t => return Err(BrickError::Message(format!("kd node tag {t}"))),
        });
    }
    let ranks = r.count(48, "kd boxes")?;
    let mut boxes: Vec<Aabb> = Vec::with_capacity(ranks);
    for _ in 0..ranks {
        boxes.push((r.f3("box")?, r.f3("box")?));
    }
    check_tree(&nodes, ranks, rank)?;
    let frame_origin = r.f3("frame origin")?;
    let range = (r.f64("range")?, r.f64("range")?);
    let support_box = (
        DVec3::from(r.f3("support box")?),
        DVec3::from(r.f3("support box")?),
    );
    let thinnest = r.f64("thinnest support")?;
    let radii = (0..r.count(8, "support radii")?)
        .map(|_| r.f64("support radius"))
        .collect::<Result<_, _>>()?;
    let extent = SupportExtent {
        support_box,
        thinnest,
        radii,
    };
    let count = GhostCount {
        own: r.u64("own samples")? as usize,
        ghosts: r.u64("ghosts")? as usize,
    };
    let positions = match r.u64("positions tag")? {
        0 => {
            let dims = [0; 3].map(|_| r.u64("grid dims").map(|d| d as usize));
            let [a, b, c] = dims;
            Positions::Grid {
                dims: [a?, b?, c?],
                origin: r.f3("grid origin")?,
                spacing: r.f3("grid spacing")?,
            }
        }
        1 => {
            let n = r.count(24, "positions")?;
            Positions::Scattered((0..n).map(|_| r.f3("position")).collect::<Result<_, _>>()?)
        }
        t => return Err(BrickError::Message(format!("positions tag {t}"))),
    };
    let storage = r.u64("value storage")?;
    let n = r.count(1, "values")?;
    let values = match storage {
        0 => Values::F32(
            r.take(n * 4, "f32 values")?
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
        ),
        1 => Values::U8(r.take(n, "u8 values")?.to_vec()),
        2 => Values::I8(
            r.take(n, "i8 values")?
                .iter()
                .map(|&b| i8::from_le_bytes([b]))
                .collect(),
        ),
        3 => Values::U16(
            r.take(n * 2, "u16 values")?
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect(),
        ),
        4 => Values::I16(
            r.take(n * 2, "i16 values")?
                .chunks_exact(2)
                .map(|b| i16::from_le_bytes([b[0], b[1]]))
                .collect(),
        ),
        t => return Err(BrickError::Message(format!("value storage {t}"))),
    };
    let count_of = match &positions {
        Positions::Grid { dims, .. } => dims
            .iter()
            .try_fold(1usize, |n, &d| n.checked_mul(d).filter(|_| d > 0))
            .ok_or_else(|| BrickError::Message(format!("grid dimensions {dims:?}")))?,
        Positions::Scattered(p) => p.len(),
    };
    if values.len() != count_of {
        return Err(BrickError::Message(format!(
            "{} values for {count_of} positions",
            values.len()
        )));
    }
    let supports = match r.u64("supports tag")? {
        0 => Supports::Uniform(r.f3("support")?),
        1 => {
            let n = r.count(48, "metrics")?;
            if n != count_of {
                return Err(BrickError::Message(format!(
                    "{n} metrics for {count_of} samples"
                )));
            }
            Supports::PerSample(
                (0..n)
                    .map(|_| {
                        let a = r.f3("metric")?;
                        let b = r.f3("metric")?;
                        Ok([a[0], a[1], a[2], b[0], b[1], b[2]])
                    })
                    .collect::<Result<_, BrickError>>()?,
            )
        }
        t => return Err(BrickError::Message(format!("supports tag {t}"))),
    };
    let domain = match r.u64("domain tag")? {
        0 => Domain::Box {
            lo: r.f3("domain")?,
            hi: r.f3("domain")?,
        },
        1 => {
            let nv = r.count(24, "hull vertices")?;
            let vertices = (0..nv).map(|_| r.f3("vertex")).collect::<Result<_, _>>()?;
            let nt = r.count(24, "hull triangles")?;
            let mut triangles = Vec::with_capacity(nt);
            for _ in 0..nt {
                let t = [0; 3].map(|_| r.index(nv, "triangle vertex"));
                let [a, b, c] = t;
                triangles.push([a? as u32, b? as u32, c? as u32]);
            }
            Domain::Hull(Hull {
                vertices,
                triangles,
            })
        }
        t => return Err(BrickError::Message(format!("domain tag {t}"))),
    };
    let spacing = r.f64("spacing")?;
    let provenance = Provenance {
        kind: r.kind("data kind")?,
        array: r.string("array")?,
        location: if r.u64("location")? == 1 {
            Location::Cell
        } else {
            Location::Point
        },
        merged: r.u64("merged")? as usize,
        inverted_cells: r.u64("inverted cells")? as usize,
        support_kind: r.kind("support kind")?,
    };
    let volumes = match r.u64("volumes tag")? {
        0 => None,
        1 => Some(KernelVolumes::Uniform(r.f64("volume")?)),
        2 => {
            let n = r.count(8, "volumes")?;
            if n != count_of {
                return Err(BrickError::Message(format!(
                    "{n} kernel volumes for {count_of} samples"
                )));
            }
            Some(KernelVolumes::PerSample(
                (0..n).map(|_| r.f64("volume")).collect::<Result<_, _>>()?,
            ))
        }
        t => return Err(BrickError::Message(format!("volumes tag {t}"))),
    };
    if r.at != bytes.len() {
        return Err(BrickError::Message(format!(
            "{} bytes past the end of the message",
            bytes.len() - r.at
        )));
    }
    Ok(BrickMessage {
        tree: KdTree { nodes, boxes },
        rank,
        frame_origin,
        range,
        extent,
        samples: SampleSet {
            positions,
            values,
            supports,
            domain,
            spacing,
            provenance,
        },
        count,
        volumes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(positions: Positions, supports: Supports, domain: Domain, n: usize) -> BrickMessage {
        BrickMessage {
            tree: KdTree {
                nodes: vec![
                    KdNode::Split {
                        axis: 2,
                        plane: 0.25,
                        below: 1,
                        above: 2,
                    },
                    KdNode::Leaf { rank: 0 },
                    KdNode::Leaf { rank: 1 },
                ],
                boxes: vec![([0.0; 3], [1.0, 1.0, 0.25]), ([0.0, 0.0, 0.25], [1.0; 3])],
            },
            rank: 1,
            frame_origin: [0.5, -2.0, 3.0],
            range: (-1.0, 4.5),
            extent: SupportExtent {
                support_box: (DVec3::new(-0.1, -0.2, -0.3), DVec3::new(1.1, 1.2, 1.3)),
                thinnest: 0.05,
                radii: vec![0.07, 0.08, 0.11],
            },
            samples: SampleSet {
                positions,
                values: Values::U16((0..n as u16).collect()),
                supports,
                domain,
                spacing: 0.1,
                provenance: Provenance {
                    kind: "unstructured mesh",
                    array: "f".into(),
                    location: Location::Cell,
                    merged: 3,
                    inverted_cells: 1,
                    support_kind: "anisotropic-one-ring",
                },
            },
            count: GhostCount { own: 2, ghosts: 1 },
            volumes: Some(KernelVolumes::PerSample(vec![0.5; n])),
        }
    }

    #[test]
    fn messages_round_trip_and_damage_is_an_error() {
        let grid = message(
            Positions::Grid {
                dims: [3, 1, 1],
                origin: [0.0; 3],
                spacing: [0.1; 3],
            },
            Supports::Uniform([0.24; 3]),
            Domain::Box {
                lo: [0.0; 3],
                hi: [1.0; 3],
            },
            3,
        );
        let mesh = message(
            Positions::Scattered(vec![[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]),
            Supports::PerSample(vec![[1.0, 2.0, 3.0, 0.1, 0.2, 0.3]; 2]),
            Domain::Hull(Hull {
                vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                triangles: vec![[0, 1, 2]],
            }),
            2,
        );
        for m in [grid, mesh] {
            let bytes = encode(&m);
            assert_eq!(decode(&bytes).unwrap(), m);
            // Every truncation, and a flipped tag, fail with an error (no panic).
            for cut in [0, 7, 8, 40, bytes.len() / 2, bytes.len() - 1] {
                assert!(decode(&bytes[..cut]).is_err(), "cut at {cut}");
            }
            let mut longer = bytes.clone();
            longer.push(0);
            assert!(decode(&longer).is_err());
            let mut bad = bytes.clone();
            bad[16] = 9;
            assert!(decode(&bad).is_err());
        }
        // A split that points at itself (a walk would never end), and a grid of no points.
        let mut looped = message(
            Positions::Scattered(vec![[0.0; 3]]),
            Supports::Uniform([1.0; 3]),
            Domain::Box {
                lo: [0.0; 3],
                hi: [1.0; 3],
            },
            1,
        );
        looped.tree.nodes[0] = KdNode::Split {
            axis: 0,
            plane: 0.5,
            below: 0,
            above: 2,
        };
        assert!(decode(&encode(&looped)).is_err());
        let mut empty = looped.clone();
        empty.tree.nodes[0] = KdNode::Split {
            axis: 0,
            plane: 0.5,
            below: 1,
            above: 2,
        };
        assert!(decode(&encode(&empty)).is_ok());
        empty.samples.positions = Positions::Grid {
            dims: [0, 1, 1],
            origin: [0.0; 3],
            spacing: [1.0; 3],
        };
        empty.samples.values = Values::U16(Vec::new());
        empty.volumes = None;
        assert!(decode(&encode(&empty)).is_err());
    }
}
