//! What a scene builds from its volume: the field (generated or loaded, checked against the
//! host's memory and the device's limits before it is built) and the views and setups the
//! renderers take.

use super::{Scene, VolumeSource};
use crate::field::{Field, RenderError};
use crate::raycast::RaySetup;
use crate::recon::resample::{AUTO_MAX_DIRECT_SHARE, AUTO_PILOT_RMSE};
use crate::samples::SampleSet;
use crate::view::camera::Camera;
use std::path::Path;

impl Scene {
    /// The scene's field: the generator's grid, or any supported file through its sample set
    /// (regular grids keep the implicit-grid path; everything else gets the octree).
    pub fn field(&self, progress: impl FnMut(f64)) -> Result<Field, RenderError> {
        self.field_on(None, progress)
    }

    /// [`Scene::field`] for a device: a regular grid whose buffer the device cannot bind is
    /// refused once its size is known (before generation; after a file is read, before the
    /// sample set, supports and fast path are built), not after all of that host work.
    pub fn field_on(
        &self,
        device: Option<&crate::vk::DeviceInfo>,
        progress: impl FnMut(f64),
    ) -> Result<Field, RenderError> {
        let grid = self.reconstruction.neighbours == crate::recon::NeighbourMode::Grid;
        let check = |samples: usize, storage| match device {
            Some(info) if grid => crate::field::gpu::GpuField::check_grid(info, samples, storage),
            _ => Ok(()),
        };
        match &self.volume {
            VolumeSource::MarschnerLobb { resolution } => {
                let n = (*resolution as u64).pow(3);
                let what = format!("volume.resolution = {resolution} ({n} samples)");
                crate::data::check_grid_host_memory(&what, n, "lower volume.resolution").map_err(
                    |message| RenderError::Setting {
                        key: "volume.resolution",
                        message,
                    },
                )?;
                check(n as usize, crate::data::Storage::F32)?;
                let volume = crate::data::marschner_lobb::generate(*resolution);
                let mut field = Field::new(volume, self.reconstruction, &self.octree, progress)?;
                self.fit_fast_path(&mut field);
                Ok(field)
            }
            VolumeSource::File { path, array } => {
                // A grid the device cannot hold is refused naming the file and what it needs:
                // from the header alone where the format allows (NRRD, NIfTI: before the data
                // is read), else once the file is loaded.
                let refused = |samples: usize, storage: crate::data::Storage| {
                    check(samples, storage).map_err(|e| {
                        RenderError::Data(crate::data::DataError::Memory {
                            path: path.clone(),
                            message: format!(
                                "its grid of {samples} {} samples cannot be held by the \
                                 device: {e}; crop or downsample the volume",
                                storage.name()
                            ),
                        })
                    })
                };
                if let Some((dims, storage)) = crate::data::grid_shape(path)? {
                    refused(dims.iter().product::<u64>() as usize, storage)?;
                }
                let dataset = crate::data::load_dataset(path)?;
                // The array the sample set will take (an unknown name is refused there).
                let values = dataset.array(path, array.as_deref()).map(|a| &a.values);
                if let (crate::data::dataset::Geometry::Image { .. }, Ok(v)) =
                    (&dataset.geometry, values)
                {
                    refused(v.len(), v.storage())?;
                }
                // The octree's indices are one texel view: built no larger than the device can
                // view, so an oversized one is refused before it is built, naming the key.
                let mut octree = self.octree;
                if let Some(info) = device {
                    octree.max_references =
                        octree.max_references.min(info.max_texel_buffer_elements);
                    octree.max_record_texels =
                        octree.max_record_texels.min(info.max_texel_buffer_elements);
                }
                self.field_from_dataset_with(&dataset, path, &octree, progress)
            }
        }
    }

    /// The field of a dataset already loaded (`path` names it in errors), with this scene's
    /// `volume.scalars`, supports, reconstruction and octree.
    pub fn field_from_dataset(
        &self,
        dataset: &crate::data::dataset::Dataset,
        path: &Path,
        progress: impl FnMut(f64),
    ) -> Result<Field, RenderError> {
        self.field_from_dataset_with(dataset, path, &self.octree, progress)
    }

    /// [`Scene::field_from_dataset`] with other octree settings (a device's limits).
    fn field_from_dataset_with(
        &self,
        dataset: &crate::data::dataset::Dataset,
        path: &Path,
        octree: &crate::recon::OctreeSettings,
        progress: impl FnMut(f64),
    ) -> Result<Field, RenderError> {
        // Loaders describe flat or vast data (`vmls info`); rendering needs a volume the f32
        // kernels can resolve.
        dataset.geometry.check_domain(path)?;
        let array = match &self.volume {
            VolumeSource::File { array, .. } => array.as_deref(),
            VolumeSource::MarschnerLobb { .. } => None,
        };
        let set =
            SampleSet::from_dataset(dataset, path, array, &self.samples).map_err(|e| match e {
                crate::samples::SampleError::Data(d) => RenderError::Data(d),
                other => RenderError::Samples(other),
            })?;
        // Splatting reads the kernels, not the octree: a splatting scene defers it to the first
        // ray-cast frame or CPU evaluation that needs it.
        if self.render.method.splat_shading().is_some() {
            return Ok(Field::from_samples_deferred(
                set,
                self.reconstruction,
                octree,
            )?);
        }
        let mut field = Field::from_samples(set, self.reconstruction, octree, progress)?;
        self.fit_fast_path(&mut field);
        Ok(field)
    }

    /// `reconstruction.resample = "auto"` takes the fast path on irregular data only where a
    /// pilot finds it accurate ([`AUTO_PILOT_RMSE`]), for MLS with the cells around barely
    /// determined fits solved directly where only that passes (and leaves at least half the
    /// pilot interpolated, [`AUTO_MAX_DIRECT_SHARE`]), and counts the first frame (issue 27 §2): the fine grid is
    /// built in the first ray-cast frame, one general-path evaluation per fine point, so "auto"
    /// keeps the fast path only where the grid has no more points than that frame would
    /// evaluate without it ([`Scene::frame_evaluations`]). The first frame then costs at most
    /// about what the general path's would, and every later one far less; where the grid is
    /// larger (a 128³ grid at 64²: 16.6 M fine points against about 2 M evaluations) the first
    /// frame would be several times slower, and "auto" solves directly. An explicit factor
    /// takes the fast path whatever the frame.
    fn fit_fast_path(&self, field: &mut Field) {
        let factor = field.reconstruction.resample;
        if !self.reconstruction.resample_auto || factor == 0 {
            return;
        }
        // Irregular data: the lattice is uniform where the samples are not, and past a
        // scattered set's outermost samples its MLS field extrapolates (the linear fit barely
        // determined, then falling back to the constant one); a pilot measures the fast path's
        // own error where the rays go. A regular grid's fast path refines a fixed convolution
        // and is bounded by tests/resample.rs.
        // The share of a frame's samples the fast path still solves (its direct cells).
        let mut direct_share = 0.0;
        if field.grid().is_none() {
            let points = self.pilot_points(field);
            let pilot = field.fast_path_pilot(&points);
            direct_share = pilot.map_or(0.0, |p| p.direct_share);
            if let Some(p) = pilot
                && p.rmse > AUTO_PILOT_RMSE
            {
                // Where the error lies in cells whose fit the samples barely determine (a
                // scattered set's field past its samples), those cells solved directly may
                // keep the rest: taken where that passes the pilot and leaves most points
                // interpolated (unless `direct_cells = false`; with true this pilot had them
                // already, and set_resample_direct keeps them off for methods without pivots).
                let retry = !field.reconstruction.resample_direct
                    && field.reconstruction.direct_cells != Some(false);
                if retry {
                    field.set_resample_direct(true);
                }
                let direct = (retry && field.reconstruction.resample_direct)
                    .then(|| field.fast_path_pilot(&points))
                    .flatten();
                if let Some(d) = direct
                    && d.rmse <= AUTO_PILOT_RMSE
                    && d.direct_share <= AUTO_MAX_DIRECT_SHARE
                {
                    direct_share = d.direct_share;
                    field.note_fast_path(format!(
                        "\"auto\" solves the fast path's cells around barely determined fits \
                         directly: at {} points along the first frame's rays its interpolation \
                         differs from the direct solve by {:.1e} of the data range in RMSE, \
                         {:.1e} with {:.0}% of them solved directly",
                        points.len(),
                        p.rmse,
                        d.rmse,
                        100.0 * d.direct_share
                    ));
                } else {
                    field.decline_fast_path(format!(
                        "\"auto\" declined the fast path: at {} points along the first frame's \
                         rays its interpolation differs from the direct solve by {:.1e} of the \
                         data range in RMSE (max {:.1e}), above auto's {AUTO_PILOT_RMSE:e}; set \
                         reconstruction.resample = {factor} to take it anyway",
                        points.len(),
                        p.rmse,
                        p.max
                    ));
                    return;
                }
            }
        }
        let Some(evaluations) = self.frame_evaluations(field) else {
            return;
        };
        let points = field.solved_fine_points();
        // Direct cells still solve their share of the frame's samples.
        let saved = ((1.0 - direct_share) * evaluations as f64) as u64;
        if points > saved {
            field.decline_fast_path(format!(
                "\"auto\" declined the fast path: its fine grid's {points} solved points (one \
                 solve each, in the first frame) exceed the {saved} solves it saves the first \
                 frame ({evaluations} without it at this image size and step); set \
                 reconstruction.resample = {factor} to take it anyway (later frames are cheaper \
                 with it)"
            ));
        }
    }

    /// Points where this scene's first frame samples the field: one at a pseudo-random depth
    /// (seeded) inside the domain on each of 16 × 16 camera rays that reach it (clipped to a
    /// mesh's hull where it has one, else to the box).
    pub fn pilot_points(&self, field: &Field) -> Vec<[f64; 3]> {
        const RAYS: u32 = 16;
        let Ok(basis) = self.camera.basis() else {
            return Vec::new();
        };
        let (lo, hi) = field.bounds();
        let mut rng = crate::data::random::Lcg::new(27);
        let mut points = Vec::new();
        for (o, d) in self.camera.sample_rays(&basis, field.frame_origin, RAYS) {
            let segments = match &field.hull {
                Some(bvh) => match bvh.segments(o.to_array(), d.to_array()) {
                    crate::samples::bvh::Segments::List(s) => s,
                    crate::samples::bvh::Segments::Overflow => Vec::new(),
                },
                None => crate::view::camera::clip_box(o, d, lo, hi)
                    .into_iter()
                    .collect(),
            };
            let inside: f64 = segments.iter().map(|(a, b)| b - a).sum();
            let mut u = rng.next_f64() * inside;
            for (a, b) in segments {
                if u <= b - a {
                    points.push((o + d * (a + u)).to_array());
                    break;
                }
                u -= b - a;
            }
        }
        points
    }

    /// Solves a first ray-cast frame of this scene would make on the general path, estimated
    /// from 32 × 32 camera rays clipped to the field's box, stepping `render.step` (adaptive:
    /// the geometric mean of `l_min` and `l_max`; early termination and a mesh's hull ignored,
    /// so an upper estimate), scaled to the image's pixels. Under `render.tolerance` the first
    /// frame is also its pilots: the fewest it renders, at the ladder's first level and the
    /// pilots' size, and the frame at that level
    /// ([`crate::renderer::tolerance::fewest_pilots`]; the ladder only refines from there, so
    /// that part is a lower estimate). `None` for a degenerate camera.
    pub fn frame_evaluations(&self, field: &Field) -> Option<u64> {
        const RAYS: u32 = 32;
        let basis = self.camera.basis().ok()?;
        let (lo, hi) = field.bounds();
        let settings = crate::renderer::tolerance::first_level(&self.render);
        let spacings = match settings.method {
            crate::view::Method::Adaptive => {
                (settings.l_min_spacings * settings.l_max_spacings).sqrt()
            }
            crate::view::Method::Reference => settings.reference_step_spacings,
            _ => settings.step_spacings,
        };
        let step = spacings * field.min_spacing();
        let length: f64 = self
            .camera
            .sample_rays(&basis, field.frame_origin, RAYS)
            .filter_map(|(o, d)| crate::view::camera::clip_box(o, d, lo, hi))
            .map(|(t0, t1)| t1 - t0)
            .sum();
        let area = |(w, h): (u32, u32)| f64::from(w.max(1)) * f64::from(h.max(1));
        let pilot = area(crate::renderer::tolerance::pilot_size(
            &self.camera,
            settings.method,
        ));
        let pixels = area((self.camera.width, self.camera.height))
            + f64::from(crate::renderer::tolerance::fewest_pilots(&self.render)) * pilot;
        Some((length / step * pixels / f64::from(RAYS * RAYS)).min(u64::MAX as f64) as u64)
    }

    /// What the persistent renderer draws for this scene: its camera and everything else.
    pub fn view(&self) -> crate::view::View<'_> {
        self.view_with(&self.camera)
    }

    /// As [`Scene::view`] with another camera (an orbit, a nudged eye).
    pub fn view_with<'a>(&'a self, camera: &'a Camera) -> crate::view::View<'a> {
        crate::view::View {
            camera,
            settings: &self.render,
            transfer: &self.transfer,
            isosurfaces: &self.isosurfaces,
            lighting: &self.lighting,
        }
    }

    /// The splatting setup of this scene's camera and settings for a field.
    pub fn splat_setup(
        &self,
        shading: crate::splat::Shading,
        field: &Field,
    ) -> Result<crate::splat::SplatSetup, RenderError> {
        let mut setup = crate::splat::SplatSetup::new(
            shading,
            &self.render.splat,
            &self.camera,
            self.render.early_termination,
            self.render.background,
            &self.isosurfaces,
            &self.lighting,
            field,
        )?;
        setup.table_resolution = self.render.table_resolution;
        setup.resolve_exact_opacity(self.render.exact_opacity, field, &self.transfer);
        Ok(setup)
    }

    /// The ray setup of this scene's camera, integrator, isosurfaces and lighting for a field.
    pub fn ray_setup(&self, field: &Field) -> Result<RaySetup, RenderError> {
        RaySetup::new(
            &self.camera,
            &self.render,
            &self.isosurfaces,
            &self.lighting,
            field,
        )
    }
}

/// Loads or generates the scene's volume.
pub fn load_volume(scene: &Scene) -> Result<crate::data::Volume, crate::data::DataError> {
    match &scene.volume {
        VolumeSource::MarschnerLobb { resolution } => {
            Ok(crate::data::marschner_lobb::generate(*resolution))
        }
        VolumeSource::File { path, array } => crate::data::load(path, array.as_deref()),
    }
}
