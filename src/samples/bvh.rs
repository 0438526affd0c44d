//! Ray–hull clipping: a bounding-volume hierarchy over a domain's boundary triangles and the
//! inside segments of a ray, f64 twin of `glsl/field/hull.glsl` (stage `hull_segments`).
//!
//! Contract:
//! - the hull's triangles face outwards ([`super::mesh`] orients them); a ray crossing one
//!   against its normal enters, along it leaves;
//! - hits use the watertight ray–triangle test of Woop, Benthin and Wald (JCGT 2013): a ray
//!   through an edge or vertex shared by several triangles is never missed. It may be counted
//!   by more than one of them: hits of the same direction at the same distance (within
//!   [`HIT_MERGE`] relative) are one crossing ([`merge_coincident`]). Counting both broke the
//!   winding below: a ray entering through a face and leaving through an edge summed to +1,
//!   which put the eye inside and made a segment from the eye (a real mesh, fire_ug.vtu,
//!   had such a ray at 512² in f32). Inside-ness is a winding number, not a parity: w(∞) = 0,
//!   walking forward an entering hit raises w by one and a leaving hit lowers it, so the
//!   winding at the eye is minus the sum of all steps ahead; the ray is inside where w > 0,
//!   and an eye inside the mesh works;
//! - at most [`MAX_HITS`] crossings per ray ahead of the eye; a ray with more gets
//!   [`Segments::Overflow`] and the render fails clearly.
//!
//! Layout (the GPU's too): nodes in depth-first preorder, `nodes[2i] = (lo.xyz, bits(first))`,
//! `nodes[2i+1] = (hi.xyz, bits(count))`. An inner node has count 0, its first child at i + 1
//! and `first` = the index just past its subtree (its escape link); a leaf's triangles are
//! `first .. first + count`, three vec4 vertices each, and the node after it is i + 1.
//! Traversal needs no stack (Smits 1998): from node i, a hit inner node goes to i + 1, a missed
//! one to its escape, a leaf to i + 1, until the root's escape (the node count). A per-lane
//! stack lives in memory on lavapipe (a dynamically indexed local array), where this walk keeps
//! one index in a register.

use super::mesh::Hull;

/// Crossings a ray may have with a hull.
pub const MAX_HITS: usize = 32;
/// Relative distance within which two hits of the same direction are one crossing: the
/// triangles around a shared edge or vertex compute its t from different vertices, which
/// differ by rounding (f32 on the GPU), never by this much on a mesh whose cells are larger
/// than 10⁻⁵ of their distance from the eye.
pub const HIT_MERGE: f64 = 1e-5;
/// Triangles per leaf, at most.
pub const LEAF_TRIANGLES: usize = 4;
/// Deepest level the build splits to (a node there becomes a leaf whatever its count).
pub const MAX_DEPTH: usize = 40;

/// One node: bounds and either two children (`count == 0`: the first at the next index,
/// `first` the escape past the subtree) or a triangle range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BvhNode {
    pub lo: [f64; 3],
    pub hi: [f64; 3],
    pub first: u32,
    pub count: u32,
}

/// A flattened BVH with its triangles in leaf order.
#[derive(Debug, Clone, PartialEq)]
pub struct HullBvh {
    pub nodes: Vec<BvhNode>,
    pub triangles: Vec<[[f64; 3]; 3]>,
}

/// The inside parts of a ray, front to back.
#[derive(Debug, Clone, PartialEq)]
pub enum Segments {
    List(Vec<(f64, f64)>),
    /// More than [`MAX_HITS`] crossings.
    Overflow,
}

fn bounds_of(tris: &[[[f64; 3]; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for t in tris {
        for v in t {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
    }
    (lo, hi)
}

impl HullBvh {
    /// BVH split by the surface-area heuristic ([`sah_split`]), by the median of the centroids
    /// along their longest axis where it finds no split.
    pub fn build(hull: &Hull) -> Self {
        let mut triangles: Vec<[[f64; 3]; 3]> = hull
            .triangles
            .iter()
            .map(|t| t.map(|i| hull.vertices[i as usize]))
            .collect();
        let mut nodes = Vec::new();
        let n = triangles.len();
        build_node(&mut nodes, &mut triangles, 0, n, 0);
        Self { nodes, triangles }
    }

    /// Inside segments of the ray o + t·d (t > 0).
    pub fn segments(&self, o: [f64; 3], d: [f64; 3]) -> Segments {
        let mut hits: Vec<(f64, i32)> = Vec::new();
        if self.triangles.is_empty() {
            return Segments::List(Vec::new());
        }
        let inv = d.map(|c| if c != 0.0 { 1.0 / c } else { f64::INFINITY });
        let mut i = 0;
        while i < self.nodes.len() {
            let node = &self.nodes[i];
            let hit = slab(o, inv, node.lo, node.hi);
            if node.count == 0 {
                i = if hit { i + 1 } else { node.first as usize };
                continue;
            }
            if hit {
                let tris = node.first as usize..(node.first + node.count) as usize;
                for t in &self.triangles[tris] {
                    if let Some((t_hit, leaving)) = intersect(o, d, t)
                        && t_hit > 0.0
                    {
                        hits.push((t_hit, if leaving { -1 } else { 1 }));
                    }
                }
            }
            i += 1;
        }
        if hits.len() > MAX_HITS {
            return Segments::Overflow;
        }
        hits.sort_by(|a, b| a.0.total_cmp(&b.0));
        merge_coincident(&mut hits);
        Segments::List(walk(&hits))
    }
}

/// Keeps one of each run of sorted hits with the same step whose distances differ by at most
/// [`HIT_MERGE`] relative: one crossing of a shared edge or vertex that several triangles hit.
pub fn merge_coincident(hits: &mut Vec<(f64, i32)>) {
    // `dedup_by` compares each hit with the last one kept.
    hits.dedup_by(|h, kept| h.1 == kept.1 && h.0 - kept.0 <= HIT_MERGE * h.0);
}

/// Turns sorted hits (t, +1 entering / −1 leaving) into inside segments.
fn walk(hits: &[(f64, i32)]) -> Vec<(f64, f64)> {
    // w just after the eye: w(∞) = 0 minus the steps crossed on the way out.
    let mut w: i32 = -hits.iter().map(|h| h.1).sum::<i32>();
    let mut out = Vec::new();
    let mut start = if w > 0 { Some(0.0) } else { None };
    for &(t, step) in hits {
        w += step;
        match (start, w > 0) {
            (None, true) => start = Some(t),
            (Some(s), false) => {
                if t > s {
                    out.push((s, t));
                }
                start = None;
            }
            _ => {}
        }
    }
    out
}

/// Appends the subtree over `tris[first..end]` in preorder.
fn build_node(
    nodes: &mut Vec<BvhNode>,
    tris: &mut [[[f64; 3]; 3]],
    first: usize,
    end: usize,
    depth: usize,
) {
    let (lo, hi) = bounds_of(&tris[first..end]);
    let count = end - first;
    let at = nodes.len();
    nodes.push(BvhNode {
        lo,
        hi,
        first: first as u32,
        count: count as u32,
    });
    if count <= LEAF_TRIANGLES || depth + 1 >= MAX_DEPTH {
        return;
    }
    let centroid = |t: &[[f64; 3]; 3], a: usize| t[0][a] + t[1][a] + t[2][a];
    let (clo, chi) = tris[first..end].iter().fold(
        ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
        |(mut l, mut h), t| {
            for a in 0..3 {
                l[a] = l[a].min(centroid(t, a));
                h[a] = h[a].max(centroid(t, a));
            }
            (l, h)
        },
    );
    let mid = match sah_split(&tris[first..end], clo, chi) {
        Some((axis, split)) => {
            // Two-pointer partition: bins below `split` first (deterministic for one input).
            let bin = |t: &[[f64; 3]; 3]| sah_bin(centroid(t, axis), clo[axis], chi[axis]);
            let part = &mut tris[first..end];
            let (mut i, mut j) = (0, part.len());
            while i < j {
                if bin(&part[i]) < split {
                    i += 1;
                } else {
                    j -= 1;
                    part.swap(i, j);
                }
            }
            i
        }
        None => {
            let axis = (0..3)
                .max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b])))
                .unwrap_or(0);
            tris[first..end].select_nth_unstable_by(count / 2, |a, b| {
                centroid(a, axis).total_cmp(&centroid(b, axis))
            });
            count / 2
        }
    };
    build_node(nodes, tris, first, first + mid, depth + 1);
    build_node(nodes, tris, first + mid, end, depth + 1);
    // Inner: the escape past the subtree.
    nodes[at].first = nodes.len() as u32;
    nodes[at].count = 0;
}

/// Bins of the surface-area heuristic per axis.
const SAH_BINS: usize = 16;

/// The SAH bin of a centroid coordinate c (three times the centroid, as `build_node` sums the
/// vertices) in [lo, hi].
fn sah_bin(c: f64, lo: f64, hi: f64) -> usize {
    (((c - lo) / (hi - lo) * SAH_BINS as f64) as usize).min(SAH_BINS - 1)
}

/// Surface area of a box (zero for an empty one).
fn area(lo: [f64; 3], hi: [f64; 3]) -> f64 {
    let d: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]).max(0.0));
    2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
}

/// The split (axis, first bin of the upper side) of binned centroids minimising the
/// surface-area heuristic A_left·N_left + A_right·N_right (MacDonald and Booth 1990; binned as
/// in Wald 2007). A ray collects every crossing, so it visits every node whose box it
/// pierces, about in proportion to the box's area: on a room-shaped hull the median split kept
/// boxes as large as the room down many levels, and the walk cost 330 of a 380 ms frame
/// (fire_ug.vtu at 512²). `None` when no split separates the centroids.
fn sah_split(tris: &[[[f64; 3]; 3]], clo: [f64; 3], chi: [f64; 3]) -> Option<(usize, usize)> {
    let mut best: Option<(f64, usize, usize)> = None;
    for axis in 0..3 {
        if chi[axis] <= clo[axis] {
            continue;
        }
        let grow = |acc: &mut ([f64; 3], [f64; 3]), b: &([f64; 3], [f64; 3])| {
            for a in 0..3 {
                acc.0[a] = acc.0[a].min(b.0[a]);
                acc.1[a] = acc.1[a].max(b.1[a]);
            }
        };
        let mut counts = [0usize; SAH_BINS];
        let mut boxes = [([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]); SAH_BINS];
        for t in tris {
            let b = sah_bin(t[0][axis] + t[1][axis] + t[2][axis], clo[axis], chi[axis]);
            counts[b] += 1;
            let (lo, hi) = bounds_of(std::slice::from_ref(t));
            grow(&mut boxes[b], &(lo, hi));
        }
        // Suffix areas and counts, then a sweep from the left.
        let mut right = [(0.0, 0usize); SAH_BINS];
        let mut acc = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let mut n = 0;
        for b in (1..SAH_BINS).rev() {
            grow(&mut acc, &boxes[b]);
            n += counts[b];
            right[b] = (area(acc.0, acc.1), n);
        }
        let mut acc = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let mut n = 0;
        for split in 1..SAH_BINS {
            grow(&mut acc, &boxes[split - 1]);
            n += counts[split - 1];
            let (ar, nr) = right[split];
            if n == 0 || nr == 0 {
                continue;
            }
            let cost = area(acc.0, acc.1) * n as f64 + ar * nr as f64;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, split));
            }
        }
    }
    best.map(|(_, axis, split)| (axis, split))
}

/// Slab test of the ray (t ≥ 0) against a box.
fn slab(o: [f64; 3], inv: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> bool {
    let mut t0: f64 = 0.0;
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        if inv[a].is_infinite() {
            if o[a] < lo[a] || o[a] > hi[a] {
                return false;
            }
            continue;
        }
        let ta = (lo[a] - o[a]) * inv[a];
        let tb = (hi[a] - o[a]) * inv[a];
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    t0 <= t1
}

/// Watertight ray–triangle intersection (Woop et al. 2013): (t, leaving) or None.
pub fn intersect(o: [f64; 3], d: [f64; 3], tri: &[[f64; 3]; 3]) -> Option<(f64, bool)> {
    let kz = (0..3)
        .max_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs()))
        .unwrap_or(2);
    let mut kx = (kz + 1) % 3;
    let mut ky = (kx + 1) % 3;
    if d[kz] < 0.0 {
        std::mem::swap(&mut kx, &mut ky);
    }
    let sx = d[kx] / d[kz];
    let sy = d[ky] / d[kz];
    let sz = 1.0 / d[kz];
    let rel = |v: [f64; 3]| [v[0] - o[0], v[1] - o[1], v[2] - o[2]];
    let (a, b, c) = (rel(tri[0]), rel(tri[1]), rel(tri[2]));
    let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
    let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
    let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let t = (u * sz * a[kz] + v * sz * b[kz] + w * sz * c[kz]) / det;
    // The swap of kx and ky for d[kz] < 0 keeps the projected frame right-handed, so the sign
    // of det says which side the ray sees (the unit tests fix the convention).
    Some((t, det < 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> Hull {
        // Unit cube, outward counter-clockwise quads split in two.
        let v: Vec<[f64; 3]> = (0..8)
            .map(|i| [(i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2 & 1) as f64])
            .collect();
        let quads = [
            [0, 4, 6, 2],
            [1, 3, 7, 5],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 2, 3, 1],
            [4, 5, 7, 6],
        ];
        let mut triangles = Vec::new();
        for q in quads {
            triangles.push([q[0], q[1], q[2]]);
            triangles.push([q[0], q[2], q[3]]);
        }
        Hull {
            vertices: v,
            triangles,
        }
    }

    #[test]
    fn rays_through_a_cube_and_its_edges_and_corners() {
        let bvh = HullBvh::build(&cube());
        // Straight through the middle.
        assert_eq!(
            bvh.segments([0.5, 0.5, -1.0], [0.0, 0.0, 1.0]),
            Segments::List(vec![(1.0, 2.0)])
        );
        // Through the diagonal of a face (the edge shared by its two triangles).
        let s = bvh.segments([0.25, 0.25, -1.0], [0.0, 0.0, 1.0]);
        assert_eq!(s, Segments::List(vec![(1.0, 2.0)]));
        // Through a corner and the opposite corner.
        let d = 1.0 / 3f64.sqrt();
        let Segments::List(s) = bvh.segments([-1.0, -1.0, -1.0], [d, d, d]) else {
            panic!("overflow")
        };
        assert_eq!(s.len(), 1);
        assert!((s[0].0 - 3f64.sqrt()).abs() < 1e-12 && (s[0].1 - 2.0 * 3f64.sqrt()).abs() < 1e-12);
        // From inside.
        let Segments::List(s) = bvh.segments([0.5, 0.5, 0.5], [1.0, 0.0, 0.0]) else {
            panic!("overflow")
        };
        assert_eq!(s, vec![(0.0, 0.5)]);
        // In through a face, out through the top face's diagonal (an edge of two triangles):
        // one crossing each way, the eye outside.
        let Segments::List(s) = bvh.segments([0.0, 1.0, -1.0], [0.25, -0.25, 1.0]) else {
            panic!("overflow")
        };
        assert_eq!(s, vec![(1.0, 2.0)]);
        // The same ray backwards: in through the edge, out through a face.
        let Segments::List(s) = bvh.segments([1.0, 0.0, 3.0], [-0.25, 0.25, -1.0]) else {
            panic!("overflow")
        };
        assert_eq!(s, vec![(2.0, 3.0)]);
        // Missing it.
        assert_eq!(
            bvh.segments([2.0, 2.0, -1.0], [0.0, 0.0, 1.0]),
            Segments::List(vec![])
        );
    }
}
