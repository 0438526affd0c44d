//! IceT's ordered sort-last compositing (the few calls vmls makes), over Debian's ParaView
//! build of IceT 2 (`libvtkIceTCore`, `libvtkIceTMPI`, header `vtkicet/src/include/IceT.h`),
//! linked by `tools/build.rs` under the `mpi` feature. Thin wrappers: one [`Icet`] owns an
//! IceT communicator and context and destroys them when dropped; every call checks
//! `icetGetError` and returns a typed error.
//!
//! The one place outside the Vulkan layer with `unsafe`: calls into IceT's C API.

use mpi::topology::SimpleCommunicator;
use mpi::traits::AsRaw;
use std::os::raw::{c_int, c_void};

type IceTEnum = u32;

/// `IceTImage`, a struct of one pointer passed by value.
#[repr(C)]
#[derive(Clone, Copy)]
struct IceTImage {
    opaque: *mut c_void,
}

const ICET_IMAGE_COLOR_RGBA_FLOAT: IceTEnum = 0xC002;
const ICET_IMAGE_DEPTH_NONE: IceTEnum = 0xD000;
const ICET_COMPOSITE_MODE_BLEND: IceTEnum = 0x0302;
const ICET_ORDERED_COMPOSITE: IceTEnum = 0x0140 | 0x0002;
const ICET_STRATEGY_REDUCE: IceTEnum = 0x6004;
const ICET_SINGLE_IMAGE_STRATEGY_BSWAP: IceTEnum = 0x7002;
const ICET_SINGLE_IMAGE_STRATEGY_TREE: IceTEnum = 0x7003;
const ICET_SINGLE_IMAGE_STRATEGY_RADIXK: IceTEnum = 0x7004;
const ICET_COMPOSITE_TIME: IceTEnum = 0x00C0 | 0x0007;
const ICET_BYTES_SENT: IceTEnum = 0x00C0 | 0x000A;
const ICET_NO_ERROR: IceTEnum = 0;

// SAFETY: these declarations match IceT.h and IceTMPI.h of Debian's ParaView 5.11 build
// (IceTEnum = u32, IceTInt = IceTSizeType = int, IceTBoolean = u8, IceTImage one pointer by
// value, MPI_Comm as the mpi crate's binding of the same OpenMPI); each call states its own
// contract where it is made.
unsafe extern "C" {
    fn icetCreateMPICommunicator(comm: mpi::ffi::MPI_Comm) -> *mut c_void;
    fn icetDestroyMPICommunicator(comm: *mut c_void);
    fn icetCreateContext(comm: *mut c_void) -> *mut c_void;
    fn icetDestroyContext(context: *mut c_void);
    fn icetSetContext(context: *mut c_void);
    fn icetSetColorFormat(format: IceTEnum);
    fn icetSetDepthFormat(format: IceTEnum);
    fn icetCompositeMode(mode: IceTEnum);
    fn icetEnable(pname: IceTEnum);
    fn icetCompositeOrder(process_ranks: *const c_int);
    fn icetStrategy(strategy: IceTEnum);
    fn icetSingleImageStrategy(strategy: IceTEnum);
    fn icetResetTiles();
    fn icetAddTile(x: c_int, y: c_int, width: c_int, height: c_int, display_rank: c_int) -> c_int;
    fn icetPhysicalRenderSize(width: c_int, height: c_int);
    fn icetCompositeImage(
        color_buffer: *const c_void,
        depth_buffer: *const c_void,
        valid_pixels_viewport: *const c_int,
        projection_matrix: *const f64,
        modelview_matrix: *const f64,
        background_color: *const f32,
    ) -> IceTImage;
    fn icetImageIsNull(image: IceTImage) -> u8;
    fn icetImageGetColorcf(image: IceTImage) -> *const f32;
    fn icetGetDoublev(pname: IceTEnum, params: *mut f64);
    fn icetGetIntegerv(pname: IceTEnum, params: *mut c_int);
    fn icetGetError() -> IceTEnum;
}

/// How IceT composites one image (`icetSingleImageStrategy`; the multi-tile strategy is
/// always `ICET_STRATEGY_REDUCE`, the one display tile being rank 0's).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Strategy {
    RadixK,
    BinarySwap,
    Tree,
}

impl Strategy {
    /// All, by their command-line names.
    pub const ALL: [(&'static str, Strategy); 3] = [
        ("radixk", Strategy::RadixK),
        ("bswap", Strategy::BinarySwap),
        ("tree", Strategy::Tree),
    ];

    fn icet(self) -> IceTEnum {
        match self {
            Strategy::RadixK => ICET_SINGLE_IMAGE_STRATEGY_RADIXK,
            Strategy::BinarySwap => ICET_SINGLE_IMAGE_STRATEGY_BSWAP,
            Strategy::Tree => ICET_SINGLE_IMAGE_STRATEGY_TREE,
        }
    }
}

/// An IceT call failed.
#[derive(Debug, thiserror::Error)]
#[error("IceT: {call} failed (icetGetError 0x{code:04x})")]
pub struct IcetError {
    pub call: &'static str,
    pub code: u32,
}

fn check(call: &'static str) -> Result<(), IcetError> {
    // SAFETY: icetGetError only reads the current context's error state, which every caller
    // of `check` has set (Icet::new creates and makes current the context first).
    let code = unsafe { icetGetError() };
    if code == ICET_NO_ERROR {
        Ok(())
    } else {
        Err(IcetError { call, code })
    }
}

/// An IceT context over an MPI communicator, set up for premultiplied RGBA32F images blended
/// in a given order.
pub struct Icet {
    communicator: *mut c_void,
    context: *mut c_void,
}

/// A composite's result on this rank: the image on the display rank (rank 0), and what it cost.
pub struct Composited {
    pub image: Option<Vec<[f32; 4]>>,
    pub stats: CompositeStats,
}

/// What one composite did on this rank.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompositeStats {
    /// IceT's `ICET_COMPOSITE_TIME` and `ICET_BYTES_SENT` for the last frame.
    pub seconds: f64,
    pub bytes_sent: i64,
}

impl Icet {
    /// Creates the context on `world` (every rank calls this, collectively).
    pub fn new(world: &SimpleCommunicator) -> Result<Self, IcetError> {
        // SAFETY: `world.as_raw()` is a valid communicator for the life of the MPI universe,
        // which outlives this value (the caller keeps both; Icet is dropped first); IceT
        // duplicates what it needs from it.
        let communicator = unsafe { icetCreateMPICommunicator(world.as_raw()) };
        if communicator.is_null() {
            return Err(IcetError {
                call: "icetCreateMPICommunicator",
                code: 0,
            });
        }
        // SAFETY: `communicator` was just created and is not null.
        let context = unsafe { icetCreateContext(communicator) };
        if context.is_null() {
            // SAFETY: created above, destroyed once.
            unsafe { icetDestroyMPICommunicator(communicator) };
            return Err(IcetError {
                call: "icetCreateContext",
                code: 0,
            });
        }
        let icet = Self {
            communicator,
            context,
        };
        // SAFETY: the context is current (icetCreateContext makes it so); these set state
        // of that context from constants of the header.
        unsafe {
            icetSetColorFormat(ICET_IMAGE_COLOR_RGBA_FLOAT);
            icetSetDepthFormat(ICET_IMAGE_DEPTH_NONE);
            icetCompositeMode(ICET_COMPOSITE_MODE_BLEND);
            icetEnable(ICET_ORDERED_COMPOSITE);
            icetStrategy(ICET_STRATEGY_REDUCE);
        }
        check("icet set-up")?;
        Ok(icet)
    }

    /// Composites every rank's `pixels` (width × height RGBA32F, premultiplied colour over a
    /// black background, the same layout on every rank) blended front to back in `order`
    /// (ranks), with `strategy`. Collective: every rank must call it with a buffer of the
    /// same size (the caller agrees on that first: a rank that returned here on a wrong size
    /// would leave the others waiting). Returns the image on rank 0, `None` elsewhere.
    pub fn composite(
        &self,
        pixels: &[[f32; 4]],
        (width, height): (u32, u32),
        order: &[usize],
        strategy: Strategy,
    ) -> Result<Composited, IcetError> {
        let (w, h) = (width as c_int, height as c_int);
        if pixels.len() != width as usize * height as usize {
            return Err(IcetError {
                call: "icetCompositeImage (buffer size)",
                code: 0,
            });
        }
        let order: Vec<c_int> = order.iter().map(|&r| r as c_int).collect();
        let viewport = [0, 0, w, h];
        let identity: [f64; 16] = [
            1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ];
        let background = [0.0f32; 4];
        // SAFETY: this context is made current first; `order` has one entry per rank, `viewport`
        // 4 ints, the matrices 16 doubles, the background 4 floats, `pixels` width × height
        // RGBA32F texels; all outlive icetCompositeImage, the only call that reads them.
        let image = unsafe {
            icetSetContext(self.context);
            icetSingleImageStrategy(strategy.icet());
            icetCompositeOrder(order.as_ptr());
            icetResetTiles();
            icetAddTile(0, 0, w, h, 0);
            icetPhysicalRenderSize(w, h);
            icetCompositeImage(
                pixels.as_ptr().cast(),
                std::ptr::null(),
                viewport.as_ptr(),
                identity.as_ptr(),
                identity.as_ptr(),
                background.as_ptr(),
            )
        };
        // SAFETY: `image` was returned by icetCompositeImage of this context and stays valid
        // until the next compositing call; a non-null image on the display rank holds width ×
        // height RGBA floats, copied out here before any other IceT call.
        let out: Option<Vec<[f32; 4]>> = unsafe {
            if icetImageIsNull(image) != 0 {
                None
            } else {
                let color = icetImageGetColorcf(image);
                (!color.is_null()).then(|| {
                    let floats = std::slice::from_raw_parts(color, pixels.len() * 4);
                    floats
                        .chunks_exact(4)
                        .map(|c| [c[0], c[1], c[2], c[3]])
                        .collect()
                })
            }
        };
        check("icetCompositeImage")?;
        let mut seconds = 0.0f64;
        let mut bytes: c_int = 0;
        // SAFETY: both state variables are scalars of the current context.
        unsafe {
            icetGetDoublev(ICET_COMPOSITE_TIME, &mut seconds);
            icetGetIntegerv(ICET_BYTES_SENT, &mut bytes);
        }
        let stats = CompositeStats {
            seconds,
            bytes_sent: i64::from(bytes),
        };
        Ok(Composited { image: out, stats })
    }
}

impl Drop for Icet {
    fn drop(&mut self) {
        // SAFETY: both were created in `new`, are destroyed once here, context first (it uses
        // the communicator).
        unsafe {
            icetDestroyContext(self.context);
            icetDestroyMPICommunicator(self.communicator);
        }
    }
}
