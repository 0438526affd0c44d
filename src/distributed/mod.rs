//! Sort-last rendering across MPI ranks with IceT compositing (issue 30; cargo feature `mpi`).
//!
//! Rank 0 reads the input, divides the field by the kd decomposition ([`crate::bricks`]) and
//! sends each rank its piece (samples and ghosts — for splatting, the kernels of the scene's
//! view that reach the rank's sheets —, the tree, the whole field's frame); every rank renders
//! its brick alone (premultiplied RGBA32F over black, rays clipped to the brick, or the sheets
//! its cell owns),
//! and IceT blends the
//! ranks' images in the kd tree's visibility order from the eye (`icetCompositeOrder`, the
//! near child first) onto rank 0, which puts the background under it. The result is the
//! virtual bricks' image ([`crate::bricks::VirtualBricks`], the same pieces on one device
//! composited in f64), up to IceT's f32 blending.
//!
//! Failures are agreed on: after each phase every rank reports whether it failed, and if any
//! did, every rank returns [`DistributedError`] and rank 0's names the first failing rank and
//! its message, so that no rank waits in a collective call for one that has gone.
//!
//! A parallel VTK XML file (`.pvti`, `.pvtr`, `.pvts`, `.pvtu`, `.pvtp`) is read by the ranks
//! instead ([`RankBrick::read_parallel`]): an image's pieces by the ranks whose bricks they
//! meet, the other kinds' pieces in shares, redistributed to the kd boxes; no rank holds the
//! whole field.
//!
//! A ray-cast rank dispatches only the pixels of its box's screen footprint
//! ([`crate::raycast::RaySetup::window`]).
//!
//! Not yet here: anisotropic supports of a `.pvtu`'s points or a `.pvts` (one-rings, grid
//! edges) are read whole by rank 0 (its memory bounds the data).
//!
//! A splatting rank draws its kernels only on the pixels and sheets its cell can own
//! ([`crate::splat::SplatSetup::window`]); its raster still walks every tile of the image.

#[allow(unsafe_code)]
mod icet;

pub use icet::{CompositeStats, IcetError, Strategy};

use crate::bricks::exchange::Exchange;
use crate::bricks::parallel::GridPlan;
use crate::bricks::parallel_scattered::read_scattered;
use crate::bricks::wire::{decode, encode};
use crate::bricks::{
    BrickError, Ghosts, brick_settings, decompose, message_for, over_background,
    piece_from_message, reach_for, splat_view, viewpoint,
};
use crate::data::vtk_xml_parallel::Summary;
use crate::field::Field;
use crate::renderer::Renderer;
use crate::view::View;
use crate::view::ViewKey;
use crate::vk::Context;
use icet::Icet;
use mpi::Count;
use mpi::collective::SystemOperation;
use mpi::datatype::{Partition, PartitionMut};
use mpi::topology::SimpleCommunicator;
use mpi::traits::{Communicator, CommunicatorCollectives, Destination, Root, Source};
use std::time::Instant;

/// Longest message a failing rank sends to rank 0, in bytes.
const MESSAGE_BYTES: usize = 1024;

/// A distributed frame failed.
#[derive(Debug, thiserror::Error)]
pub enum DistributedError {
    /// On rank 0: the first rank that failed and what it said.
    #[error("rank {rank} of {ranks}: {message}")]
    Rank {
        rank: i32,
        ranks: i32,
        message: String,
    },
    /// On the other ranks: some rank failed (rank 0 reports which).
    #[error("rank {rank}: stopped, rank 0 reports the failure")]
    Elsewhere { rank: i32 },
}

/// Every rank calls this with its outcome of a phase; `Ok` on all ranks only if no rank failed.
pub fn agree<T>(
    world: &SimpleCommunicator,
    local: Result<T, String>,
) -> Result<T, DistributedError> {
    let failed = i32::from(local.is_err());
    let mut any = 0i32;
    world.all_reduce_into(&failed, &mut any, SystemOperation::max());
    let local = match local {
        Ok(v) if any == 0 => return Ok(v),
        Ok(_) => None,
        Err(m) => Some(m),
    };
    let mut mine = [0u8; MESSAGE_BYTES];
    if let Some(m) = &local {
        // A non-empty message marks the failing rank; cut at a character boundary.
        let mut end = m.len().min(MESSAGE_BYTES);
        while !m.is_char_boundary(end) {
            end -= 1;
        }
        let text = if m.is_empty() { "failed" } else { &m[..end] };
        mine[..text.len()].copy_from_slice(text.as_bytes());
    }
    let root = world.process_at_rank(0);
    let rank = world.rank();
    if rank != 0 {
        root.gather_into(&mine[..]);
        return Err(DistributedError::Elsewhere { rank });
    }
    let mut all = vec![0u8; MESSAGE_BYTES * world.size() as usize];
    root.gather_into_root(&mine[..], &mut all[..]);
    let (first, text) = all
        .chunks_exact(MESSAGE_BYTES)
        .enumerate()
        .find(|(_, m)| m[0] != 0)
        .map(|(r, m)| {
            let end = m.iter().position(|&b| b == 0).unwrap_or(m.len());
            (r as i32, String::from_utf8_lossy(&m[..end]).into_owned())
        })
        .unwrap_or((0, "failed".into()));
    Err(DistributedError::Rank {
        rank: first,
        ranks: world.size(),
        message: text,
    })
}

/// The world's ranks as a [`crate::bricks::exchange::Exchange`]: MPI's variable-count
/// collectives, in rounds of at most [`ROUND`] bytes a rank sends, as their counts are 32-bit.
struct Mpi<'a>(&'a SimpleCommunicator);

/// Bytes a rank sends in one round of an exchange, at most.
const ROUND: usize = 1 << 30;

/// Displacements of `counts` laid end to end.
fn displacements(counts: &[Count]) -> Vec<Count> {
    counts
        .iter()
        .scan(0, |at, &c| {
            let d = *at;
            *at += c;
            Some(d)
        })
        .collect()
}

impl Mpi<'_> {
    /// Whether any rank has `left` bytes still to send.
    fn any_left(&self, left: usize) -> bool {
        let mut any = 0u64;
        self.0
            .all_reduce_into(&(left as u64), &mut any, SystemOperation::sum());
        any > 0
    }
}

impl Exchange for Mpi<'_> {
    type Error = DistributedError;

    fn rank(&self) -> usize {
        self.0.rank() as usize
    }

    fn size(&self) -> usize {
        self.0.size() as usize
    }

    fn all_gather(&self, bytes: Vec<u8>) -> Vec<Vec<u8>> {
        let n = self.size();
        let mut got = vec![Vec::new(); n];
        let mut at = 0;
        while self.any_left(bytes.len() - at) {
            let part = &bytes[at..(at + ROUND / n).min(bytes.len())];
            at += part.len();
            let mut counts = vec![0 as Count; n];
            self.0
                .all_gather_into(&(part.len() as Count), &mut counts[..]);
            let displs = displacements(&counts);
            let mut buf = vec![0u8; counts.iter().map(|&c| c as usize).sum()];
            let mut into = PartitionMut::new(&mut buf[..], &counts[..], &displs[..]);
            self.0.all_gather_varcount_into(part, &mut into);
            for r in 0..n {
                let d = displs[r] as usize;
                got[r].extend_from_slice(&buf[d..d + counts[r] as usize]);
            }
        }
        got
    }

    fn all_to_all(&self, out: Vec<Vec<u8>>) -> Vec<Vec<u8>> {
        let n = self.size();
        let mut got = vec![Vec::new(); n];
        let mut at = vec![0usize; n];
        let left = |at: &[usize]| (0..n).map(|r| out[r].len() - at[r]).sum::<usize>();
        while self.any_left(left(&at)) {
            let sizes: Vec<Count> = (0..n)
                .map(|r| (out[r].len() - at[r]).min(ROUND / n) as Count)
                .collect();
            let mut send = Vec::with_capacity(sizes.iter().map(|&c| c as usize).sum());
            for r in 0..n {
                send.extend_from_slice(&out[r][at[r]..at[r] + sizes[r] as usize]);
                at[r] += sizes[r] as usize;
            }
            let mut counts = vec![0 as Count; n];
            self.0.all_to_all_into(&sizes[..], &mut counts[..]);
            let (sd, rd) = (displacements(&sizes), displacements(&counts));
            let mut buf = vec![0u8; counts.iter().map(|&c| c as usize).sum()];
            let from = Partition::new(&send[..], &sizes[..], &sd[..]);
            let mut into = PartitionMut::new(&mut buf[..], &counts[..], &rd[..]);
            self.0.all_to_all_varcount_into(&from, &mut into);
            for r in 0..n {
                let d = rd[r] as usize;
                got[r].extend_from_slice(&buf[d..d + counts[r] as usize]);
            }
        }
        got
    }

    fn agree<T>(&self, local: Result<T, String>) -> Result<T, DistributedError> {
        agree(self.0, local)
    }
}

/// One rank's share of a frame, as rank 0 gathers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RankReport {
    pub rank: i32,
    /// Samples in its box (a grid's face planes in both bricks) and ghosts.
    pub samples: u64,
    pub ghosts: u64,
    /// Its piece's build (ghost selection and octree), host ms.
    pub divide_ms: f64,
    /// Pieces of a parallel image it read itself (0: rank 0 sent its piece).
    pub pieces_read: u64,
    /// Its brick's frame: GPU ms and wall ms.
    pub render_gpu_ms: f64,
    pub render_wall_ms: f64,
    /// IceT's composite time (ms) and bytes this rank sent.
    pub composite_ms: f64,
    pub bytes_sent: f64,
}

/// A distributed frame on rank 0.
#[derive(Debug, Clone)]
pub struct DistributedFrame {
    /// (C + T·background, 1 − T) per pixel.
    pub pixels: Vec<[f64; 4]>,
    /// The ranks front to back.
    pub order: Vec<usize>,
    pub ranks: Vec<RankReport>,
    /// Wall ms of the composite on rank 0 (IceT's call and the background).
    pub composite_wall_ms: f64,
}

/// What rank 0 sends in place of a piece it could not build, before the error's text.
const FAILED: &[u8] = b"VMLSFAIL";

/// Bytes per message part: MPI counts are 32-bit.
const PART: usize = 1 << 30;

/// Sends `bytes` to rank `to`: their length, then parts of at most [`PART`] bytes.
fn send(world: &SimpleCommunicator, to: i32, bytes: &[u8]) {
    let p = world.process_at_rank(to);
    p.send(&(bytes.len() as u64));
    for part in bytes.chunks(PART) {
        p.send(part);
    }
}

/// What [`send`] sent, from `from`.
fn receive(from: &mpi::topology::Process<'_>) -> Vec<u8> {
    let (len, _) = from.receive::<u64>();
    let mut bytes = Vec::with_capacity(len as usize);
    while bytes.len() < len as usize {
        let (part, _) = from.receive_vec::<u8>();
        if part.is_empty() {
            break;
        }
        bytes.extend_from_slice(&part);
    }
    bytes
}

/// This rank's brick of `field`: the rank's piece, rendered by a renderer of its own.
pub struct RankBrick {
    renderer: Renderer,
    order_tree: crate::bricks::kd::KdTree,
    samples: u64,
    ghosts: u64,
    divide_ms: f64,
    pieces_read: usize,
    icet: Icet,
    /// Splatting bricks: the view their kernels were chosen for.
    splat_view: Option<ViewKey>,
}

impl RankBrick {
    /// Rank 0 divides `field` (which only it holds) for the world's ranks and sends each
    /// rank its piece ([`crate::bricks::wire`]); every rank builds its piece with the scene's
    /// `reconstruction` and `octree` settings and prepares its renderer and IceT. The bricks
    /// render `view` (every rank reads the scene): ray casting any view of the field,
    /// splatting this one, whose kernels rank 0 chooses for each brick. Collective; every
    /// phase is agreed on.
    pub fn scatter(
        world: &SimpleCommunicator,
        ctx: &Context,
        field: Option<&Field>,
        view: &View<'_>,
        reconstruction: crate::recon::Reconstruction,
        octree: crate::recon::OctreeSettings,
    ) -> Result<Self, DistributedError> {
        let start = Instant::now();
        let size = world.size() as usize;
        let root = world.process_at_rank(0);
        let mine: Result<Vec<u8>, String> = if world.rank() == 0 {
            // The tree is agreed on first; then each rank's piece is built, sent and dropped in
            // turn, so that rank 0 holds one encoded piece at a time beside the field. A piece
            // that cannot be built is sent as its error, which its rank reports in the next
            // agreement.
            let divided = field
                .ok_or_else(|| "rank 0 holds no field".to_string())
                .and_then(|f| {
                    let tree = decompose(f, size).map_err(|e| e.to_string())?;
                    let reach = reach_for(f, view).map_err(|e| e.to_string())?;
                    Ok((f, tree, reach))
                });
            let (field, tree, reach) = agree(world, divided)?;
            let ghosts = reach.as_ref().map_or(Ghosts::Mls, Ghosts::Splat);
            let encoded = |r: usize| {
                message_for(field, &tree, r, ghosts)
                    .map(|m| encode(&m))
                    .map_err(|e| e.to_string())
            };
            for r in 1..size {
                let bytes = encoded(r).unwrap_or_else(|e| [FAILED, e.as_bytes()].concat());
                send(world, r as i32, &bytes);
            }
            encoded(0)
        } else {
            agree(world, Ok(()))?;
            let bytes = receive(&root);
            match bytes.strip_prefix(FAILED) {
                Some(error) => Err(String::from_utf8_lossy(error).into_owned()),
                None => Ok(bytes),
            }
        };
        let (rank, ranks) = (world.rank() as usize, size);
        let piece = agree(
            world,
            mine.and_then(|bytes| {
                let m = decode(&bytes).map_err(|e| e.to_string())?;
                if m.rank != rank || m.tree.boxes.len() != ranks {
                    return Err(format!(
                        "a brick message for rank {} of {} reached rank {rank} of {ranks}",
                        m.rank,
                        m.tree.boxes.len()
                    ));
                }
                piece_from_message(m, reconstruction, octree).map_err(|e| e.to_string())
            }),
        )?;
        let divide_ms = start.elapsed().as_secs_f64() * 1e3;
        let (piece, tree, count) = piece;
        let cost = (count, divide_ms, 0);
        Self::prepare(world, ctx, piece, tree, cost, splat_view(view))
    }

    /// Every rank reads the summary of the parallel file at `path` and a part of its pieces,
    /// so that no rank holds the whole field ([`crate::bricks::parallel::ranks_read`] says
    /// which files): of an image (`.pvti`), the pieces that meet its brick and
    /// its ghost planes ([`GridPlan`]; the ranks agree on the value range); of the other kinds
    /// (`.pvtr`, `.pvts`, `.pvtu`, `.pvtp`), a contiguous share, redistributed to the kd boxes
    /// with exact supports and ghosts ([`read_scattered`]). The bricks are those
    /// [`RankBrick::scatter`] would send (under the tree their gathered subsample cuts), for
    /// ray casting or splatting `view` (an image's splatting brick: the sub-grid holding the
    /// kernels its sheets need, [`GridPlan::read_splat_brick`]). Collective; every phase is
    /// agreed on.
    #[allow(clippy::too_many_arguments)]
    pub fn read_parallel(
        world: &SimpleCommunicator,
        ctx: &Context,
        path: &std::path::Path,
        array: Option<&str>,
        samples: &crate::samples::SampleSettings,
        view: &View<'_>,
        reconstruction: crate::recon::Reconstruction,
        octree: crate::recon::OctreeSettings,
    ) -> Result<Self, DistributedError> {
        let start = Instant::now();
        let (rank, ranks) = (world.rank() as usize, world.size() as usize);
        let summary = agree(world, Summary::read(path).map_err(|e| e.to_string()))?;
        if summary.kind != "ImageData" {
            let brick = read_scattered(
                &Mpi(world),
                &summary,
                array,
                samples,
                reconstruction,
                octree,
                Some(view),
            )?;
            let piece = agree(world, brick.piece().map_err(|e| e.to_string()))?;
            let (piece, tree, count, pieces_read) = piece;
            let cost = (count, start.elapsed().as_secs_f64() * 1e3, pieces_read);
            return Self::prepare(world, ctx, piece, tree, cost, splat_view(view));
        }
        let plan = agree(
            world,
            GridPlan::new(summary, array, samples, ranks).map_err(|e| e.to_string()),
        )?;
        if view.settings.method.splat_shading().is_some() {
            let (piece, count, pieces_read) =
                plan.read_splat_brick(&Mpi(world), samples, view, reconstruction, octree)?;
            let cost = (count, start.elapsed().as_secs_f64() * 1e3, pieces_read);
            return Self::prepare(world, ctx, piece, plan.tree, cost, splat_view(view));
        }
        let brick = agree(
            world,
            plan.read_brick(rank, samples).map_err(|e| e.to_string()),
        )?;
        // Every sample is some rank's: the extremes over the ranks are the whole field's.
        let (mut lo, mut hi) = (0.0f64, 0.0f64);
        world.all_reduce_into(&brick.range.0, &mut lo, SystemOperation::min());
        world.all_reduce_into(&brick.range.1, &mut hi, SystemOperation::max());
        let (count, pieces_read) = (brick.count, brick.pieces_read);
        let piece = agree(
            world,
            plan.piece(rank, brick, (lo, hi), reconstruction, octree)
                .map_err(|e| e.to_string()),
        )?;
        let cost = (count, start.elapsed().as_secs_f64() * 1e3, pieces_read);
        Self::prepare(world, ctx, piece, plan.tree, cost, None)
    }

    /// A rank's renderer for its piece and its IceT context (collective); `cost` is the
    /// piece's sample counts, build ms and pieces of a parallel file read.
    fn prepare(
        world: &SimpleCommunicator,
        ctx: &Context,
        piece: Field,
        tree: crate::bricks::kd::KdTree,
        (count, divide_ms, pieces_read): (crate::bricks::ghosts::GhostCount, f64, usize),
        splat_view: Option<ViewKey>,
    ) -> Result<Self, DistributedError> {
        let renderer = agree(
            world,
            Renderer::new(ctx, piece).map_err(|e| BrickError::from(e).to_string()),
        )?;
        let icet = agree(world, Icet::new(world).map_err(|e| e.to_string()))?;
        Ok(Self {
            renderer,
            order_tree: tree,
            samples: count.own as u64,
            ghosts: count.ghosts as u64,
            divide_ms,
            pieces_read,
            icet,
            splat_view,
        })
    }

    /// The field of this rank's brick.
    pub fn field(&self) -> &Field {
        self.renderer.field()
    }

    /// Renders `view` across the ranks and composites it with `strategy` (collective). Rank 0
    /// gets the frame, the others `None`.
    pub fn render(
        &mut self,
        world: &SimpleCommunicator,
        view: &View<'_>,
        strategy: Strategy,
    ) -> Result<Option<DistributedFrame>, DistributedError> {
        let start = Instant::now();
        let rendered = brick_settings(view, self.splat_view.as_ref())
            .and_then(|settings| {
                let v = View {
                    settings: &settings,
                    ..*view
                };
                Ok(self.renderer.render(&v, |_| {})?)
            })
            .map_err(|e| e.to_string());
        // The composite is collective: a wrong-sized image is refused by every rank before it.
        let size = (view.camera.width, view.camera.height);
        let rendered = rendered.and_then(|(image, stats)| {
            if image.pixels.len() == size.0 as usize * size.1 as usize {
                Ok((image, stats))
            } else {
                Err(format!(
                    "a frame of {} pixels for a {}x{} image",
                    image.pixels.len(),
                    size.0,
                    size.1
                ))
            }
        });
        let (image, stats) = agree(world, rendered)?;
        let render_wall_ms = start.elapsed().as_secs_f64() * 1e3;
        let order = self
            .order_tree
            .visibility_order(viewpoint(view.camera, self.renderer.field().frame_origin));
        let start = Instant::now();
        let composited = self
            .icet
            .composite(&image.pixels, size, &order, strategy)
            .map_err(|e| e.to_string());
        let composited = agree(world, composited)?;
        let (out, composite) = (composited.image, composited.stats);
        let report = [
            f64::from(world.rank()),
            self.samples as f64,
            self.ghosts as f64,
            self.divide_ms,
            self.pieces_read as f64,
            stats.gpu_ms,
            render_wall_ms,
            composite.seconds * 1e3,
            composite.bytes_sent as f64,
        ];
        let root = world.process_at_rank(0);
        if world.rank() != 0 {
            root.gather_into(&report[..]);
            return Ok(None);
        }
        let mut all = vec![0.0f64; report.len() * world.size() as usize];
        root.gather_into_root(&report[..], &mut all[..]);
        let ranks = all
            .chunks_exact(report.len())
            .map(|r| RankReport {
                rank: r[0] as i32,
                samples: r[1] as u64,
                ghosts: r[2] as u64,
                divide_ms: r[3],
                pieces_read: r[4] as u64,
                render_gpu_ms: r[5],
                render_wall_ms: r[6],
                composite_ms: r[7],
                bytes_sent: r[8],
            })
            .collect();
        let background = view.settings.background;
        let Some(pixels) = out else {
            return Err(DistributedError::Rank {
                rank: 0,
                ranks: world.size(),
                message: "IceT returned no image on the display rank".into(),
            });
        };
        let pixels = pixels
            .iter()
            .map(|&p| over_background(p, background))
            .collect();
        Ok(Some(DistributedFrame {
            pixels,
            order,
            ranks,
            composite_wall_ms: start.elapsed().as_secs_f64() * 1e3,
        }))
    }
}
