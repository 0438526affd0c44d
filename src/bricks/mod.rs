//! Sort-last rendering of a field divided into bricks (issue 30): a kd decomposition with one
//! box per rank ([`kd`]), each brick's samples with exact ghosts ([`ghosts`]), each brick
//! rendered alone — ray cast with its rays clipped to its box and steps anchored to the
//! undivided ray ([`crate::raycast::RaySetup::clip`]), or splatted compositing the sheets its
//! cell owns ([`splat`]) — and the bricks' premultiplied images composited front to back in the
//! kd tree's visibility order.
//!
//! [`VirtualBricks`] renders the whole decomposition on one device and composites in f64: the
//! reference for a distributed run (which renders the same pieces on several devices and
//! composites them in the same order).
//!
//! What a brick's image equals: inside its box the field is the undivided one (the ghosts),
//! and its ray samples lie where the undivided frame's do; only the interval that a box face
//! splits differs, composited as two clipped intervals with a knot evaluated on the face
//! instead of one interval. Early ray termination acts within a brick and never across, so a
//! ray the undivided frame stopped at opacity o_et can still gather up to 1 − o_et behind it.
//! The adaptive integrator's Hermite criterion keeps the undivided ray's top intervals and
//! their dyadic units (a clipped interval reaches the first unit past the face); its choices
//! inside depend on the knots, so a brick's can differ after the face. A splatting brick's image
//! is the undivided frame's sheets it owns, whole ([`splat`]): the composite equals the
//! undivided frame to rounding, but its bricks hold the kernels of one view. Not yet here:
//! [MLS]'s criterion, the fast path and skipping (a brick solves directly), render.tolerance,
//! surface splats.

mod distribute;
pub mod exchange;
pub mod ghosts;
pub mod kd;
pub mod parallel;
pub mod parallel_scattered;
mod part;
pub mod splat;
pub mod wire;

pub use wire::BrickMessage;

use crate::field::{Field, PieceFrame, RenderError};
use crate::recon::gaussian::KernelVolumes;
use crate::recon::{ReconError, ReconMethod};
use crate::renderer::Renderer;
use crate::view::ViewKey;
use crate::view::camera::{Camera, Projection};
use crate::view::{RenderSettings, View};
use crate::vk::Context;
pub use ghosts::Ghosts;
use ghosts::{GhostCount, brick_samples};
use glam::DVec3;
use kd::{KdTree, Viewpoint};
use splat::SplatReach;
use std::time::Instant;

/// An axis-aligned box: lower and upper corner.
pub type Aabb = ([f64; 3], [f64; 3]);

/// Errors of the decomposition and of rendering its bricks.
#[derive(Debug, thiserror::Error)]
pub enum BrickError {
    #[error("bricks: {0}")]
    Ranks(String),
    #[error("bricks: {key}: {message}")]
    Setting { key: &'static str, message: String },
    #[error("bricks: a brick message: {0}")]
    Message(String),
    #[error("bricks: {0}")]
    Recon(#[from] ReconError),
    #[error(transparent)]
    Data(#[from] crate::data::DataError),
    #[error(transparent)]
    Render(#[from] RenderError),
}

/// The pieces of `field` for `ranks` ranks: the kd tree and, per rank, the piece of the field
/// its brick renders (with `ghosts`) and its sample counts.
pub fn divide(
    field: &Field,
    ranks: usize,
    ghosts: Ghosts<'_>,
) -> Result<(KdTree, Vec<(Field, GhostCount)>), BrickError> {
    let tree = decompose(field, ranks)?;
    let pieces = (0..ranks)
        .map(|rank| piece_of(field, &tree, rank, ghosts))
        .collect::<Result<Vec<_>, BrickError>>()?;
    Ok((tree, pieces))
}

/// The kd tree of `field` for `ranks` ranks (the analytic field, which reads no samples, is
/// refused).
pub fn decompose(field: &Field, ranks: usize) -> Result<KdTree, BrickError> {
    if field.reconstruction.method == ReconMethod::Exact {
        return Err(BrickError::Setting {
            key: "reconstruction.method",
            message: "\"exact\" is the generator's analytic field, which has no samples to \
                      divide between bricks; use \"mls\" or \"gaussian\""
                .into(),
        });
    }
    KdTree::decompose(&field.samples, ranks)
}

/// The piece of `field` that `rank`'s brick of `tree` renders, and its sample counts.
pub fn piece_of(
    field: &Field,
    tree: &KdTree,
    rank: usize,
    ghosts: Ghosts<'_>,
) -> Result<(Field, GhostCount), BrickError> {
    let m = message_for(field, tree, rank, ghosts)?;
    let bounds = tree.boxes[rank];
    let piece = field.piece(
        m.samples,
        (DVec3::from(bounds.0), DVec3::from(bounds.1)),
        m.volumes,
        |_| {},
    )?;
    Ok((piece, m.count))
}

/// What `rank` needs to build its piece of `field` without it ([`piece_from_message`]): the
/// tree, the whole field's frame, its brick's samples (with `ghosts`) and kernel volumes.
pub fn message_for(
    field: &Field,
    tree: &KdTree,
    rank: usize,
    ghosts: Ghosts<'_>,
) -> Result<BrickMessage, BrickError> {
    let bounds = tree.boxes[rank];
    let brick = brick_samples(&field.samples, bounds, |x| tree.owner(x) == rank, ghosts);
    if brick.samples.is_empty() {
        return Err(BrickError::Ranks(format!(
            "rank {rank}'s brick holds no samples; use fewer ranks"
        )));
    }
    // The Gaussian sum's and the splats' SPH volumes depend on each sample's neighbours, which
    // a brick's outermost ghosts lack: the whole field's are kept.
    let splats = matches!(ghosts, Ghosts::Splat(_));
    let volumes = (splats || field.reconstruction.method == ReconMethod::Gaussian).then(|| {
        match field.kernel_volumes() {
            KernelVolumes::Uniform(v) => KernelVolumes::Uniform(*v),
            KernelVolumes::PerSample(v) => {
                KernelVolumes::PerSample(brick.indices.iter().map(|&i| v[i]).collect())
            }
        }
    });
    Ok(BrickMessage {
        tree: tree.clone(),
        rank,
        frame_origin: field.frame_origin.to_array(),
        range: field.value_range(),
        extent: field.support_extent(),
        samples: brick.samples,
        count: brick.count,
        volumes,
    })
}

/// The piece a [`BrickMessage`] describes, with the scene's `reconstruction` and `octree`
/// settings (every rank reads the scene; only one reads the data).
pub fn piece_from_message(
    m: BrickMessage,
    reconstruction: crate::recon::Reconstruction,
    octree: crate::recon::OctreeSettings,
) -> Result<(Field, KdTree, GhostCount), BrickError> {
    let bounds = m.tree.boxes[m.rank];
    let frame = PieceFrame {
        frame_origin: DVec3::from(m.frame_origin),
        range: m.range,
        reconstruction,
        octree,
        extent: Some(m.extent),
    };
    let piece = Field::from_piece(
        m.samples,
        frame,
        (DVec3::from(bounds.0), DVec3::from(bounds.1)),
        m.volumes,
        |_| {},
    )?;
    Ok((piece, m.tree, m.count))
}

/// Composites the bricks' images front to back, in f64: each image is (C, 1 − T) with C
/// premultiplied over a black background (a brick frame's pixels), `order` lists them front to
/// back; the result is (C + T·background, 1 − T), the one-device frame's pixel.
pub fn composite(images: &[&[[f32; 4]]], order: &[usize], background: [f64; 3]) -> Vec<[f64; 4]> {
    let n = images.first().map_or(0, |i| i.len());
    (0..n)
        .map(|p| {
            let mut c = [0.0f64; 3];
            let mut t = 1.0f64;
            for &b in order {
                let px = images[b][p];
                for k in 0..3 {
                    c[k] += t * f64::from(px[k]);
                }
                t *= 1.0 - f64::from(px[3]);
            }
            [
                c[0] + t * background[0],
                c[1] + t * background[1],
                c[2] + t * background[2],
                1.0 - t,
            ]
        })
        .collect()
}

/// The settings a brick renders `view` with (over a black background, composited over the
/// view's afterwards), or the refusal of what bricks cannot render. `splat_view` is the view
/// the bricks' splatting ghosts were chosen for (none: MLS ghosts, for ray casting).
pub fn brick_settings(
    view: &View<'_>,
    splat_view: Option<&ViewKey>,
) -> Result<RenderSettings, BrickError> {
    if view.settings.tolerance.is_some() {
        return Err(BrickError::Setting {
            key: "render.tolerance",
            message: "bricks render with the scene's step: a tolerance's pilot frames would \
                      choose it per brick; give render.step instead"
                .into(),
        });
    }
    let splats = view.settings.method.splat_shading().is_some();
    match splat_view {
        Some(key) if *key != ViewKey::of(view) => {
            return Err(BrickError::Setting {
                key: "camera",
                message: "splatting bricks hold the kernels of the view they were divided for \
                          (which kernels reach a brick's sheets depends on the camera, the \
                          transfer function and the splat settings): divide again for this view"
                    .into(),
            });
        }
        None if splats => {
            return Err(BrickError::Setting {
                key: "render.method",
                message: format!(
                    "\"{}\" splats, but these bricks were divided for ray casting (MLS ghosts); \
                     divide them for the splatting view",
                    view.settings.method.name()
                ),
            });
        }
        _ => {}
    }
    let mut settings = view.settings.clone();
    settings.background = [0.0; 3];
    Ok(settings)
}

/// The view splatting bricks divided for `view` serve (they render no other); none for ray
/// casting, whose MLS ghosts serve every view.
pub fn splat_view(view: &View<'_>) -> Option<ViewKey> {
    view.settings
        .method
        .splat_shading()
        .map(|_| ViewKey::of(view))
}

/// What a decomposition's bricks need to render `view`: for ray casting nothing (MLS ghosts,
/// good for any view), for splatting the reach of every kernel in this view (projected here),
/// which chooses their ghosts ([`Ghosts::Splat`]).
pub fn reach_for(field: &Field, view: &View<'_>) -> Result<Option<SplatReach>, BrickError> {
    if view.settings.method.splat_shading().is_none() {
        return Ok(None);
    }
    Ok(Some(SplatReach::new(field, view)?))
}

/// A composited pixel over `background`: (C, α) premultiplied over black becomes
/// (C + (1 − α)·background, α), in f64.
pub fn over_background(p: [f32; 4], background: [f64; 3]) -> [f64; 4] {
    let t = 1.0 - f64::from(p[3]);
    [
        f64::from(p[0]) + t * background[0],
        f64::from(p[1]) + t * background[1],
        f64::from(p[2]) + t * background[2],
        f64::from(p[3]),
    ]
}

/// Where `camera`'s rays come from, frame-relative, for the visibility order: its eye, or for an
/// orthographic camera the direction all its rays travel (they start on the image plane, not at
/// the eye).
pub fn viewpoint(camera: &Camera, frame_origin: DVec3) -> Viewpoint {
    match (camera.projection, camera.basis()) {
        (Projection::Orthographic { .. }, Ok(basis)) => {
            Viewpoint::Direction(basis.forward.to_array())
        }
        _ => Viewpoint::Eye((DVec3::from(camera.eye) - frame_origin).to_array()),
    }
}

/// What one brick's frame cost.
#[derive(Debug, Clone, PartialEq)]
pub struct BrickStats {
    pub rank: usize,
    pub bounds: Aabb,
    pub samples: GhostCount,
    pub gpu_ms: f64,
    pub evaluations: u64,
}

/// A composited frame of the bricks.
#[derive(Debug, Clone)]
pub struct BrickFrame {
    pub pixels: Vec<[f64; 4]>,
    /// The ranks front to back.
    pub order: Vec<usize>,
    pub bricks: Vec<BrickStats>,
    /// Host milliseconds of the f64 composite.
    pub composite_ms: f64,
}

/// The whole decomposition rendered on one device ("virtual bricks"): one renderer per brick.
pub struct VirtualBricks {
    tree: KdTree,
    renderers: Vec<Renderer>,
    counts: Vec<GhostCount>,
    /// Splatting bricks: the view their kernels were chosen for.
    splat_view: Option<ViewKey>,
}

impl VirtualBricks {
    /// Divides `field` for `ranks` bricks that render `view` (ray casting: any view of the
    /// field; splatting: this one) and prepares a renderer for each.
    pub fn new(
        ctx: &Context,
        field: &Field,
        ranks: usize,
        view: &View<'_>,
    ) -> Result<Self, BrickError> {
        let reach = reach_for(field, view)?;
        let ghosts = reach.as_ref().map_or(Ghosts::Mls, Ghosts::Splat);
        let (tree, pieces) = divide(field, ranks, ghosts)?;
        let mut renderers = Vec::with_capacity(ranks);
        let mut counts = Vec::with_capacity(ranks);
        for (piece, count) in pieces {
            renderers.push(Renderer::new(ctx, piece)?);
            counts.push(count);
        }
        Ok(Self {
            tree,
            renderers,
            counts,
            splat_view: splat_view(view),
        })
    }

    /// The decomposition.
    pub fn tree(&self) -> &KdTree {
        &self.tree
    }

    /// Renders every brick of `view` (over a black background) and composites them in the
    /// visibility order from the view's eye over the view's background.
    pub fn render(&mut self, view: &View<'_>) -> Result<BrickFrame, BrickError> {
        let settings = brick_settings(view, self.splat_view.as_ref())?;
        let brick_view = View {
            settings: &settings,
            ..*view
        };
        let mut images = Vec::with_capacity(self.renderers.len());
        let mut bricks = Vec::with_capacity(self.renderers.len());
        for (rank, renderer) in self.renderers.iter_mut().enumerate() {
            let (image, stats) = renderer.render(&brick_view, |_| {})?;
            bricks.push(BrickStats {
                rank,
                bounds: self.tree.boxes[rank],
                samples: self.counts[rank],
                gpu_ms: stats.gpu_ms,
                evaluations: image.counts.iter().map(|&c| u64::from(c)).sum(),
            });
            images.push(image.pixels);
        }
        let start = Instant::now();
        let order = self.tree.visibility_order(viewpoint(
            view.camera,
            self.renderers[0].field().frame_origin,
        ));
        let refs: Vec<&[[f32; 4]]> = images.iter().map(|i| i.as_slice()).collect();
        let pixels = composite(&refs, &order, view.settings.background);
        Ok(BrickFrame {
            pixels,
            order,
            bricks,
            composite_ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }
}
