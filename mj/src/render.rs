//! MuJoCo's own renderer (`mjv_updateScene`, `mjr_render`, `mjr_readPixels`) offscreen, on an
//! OpenGL context of its own that lives on its own thread ([`GlThread`]): colour, depth and
//! segmentation images of a camera, top row first (as `sensor_msgs/Image`; OpenGL reads
//! bottom-up). The same calls and flags as MuJoCo's Python `Renderer`, so a frame equals that
//! one's for the same model, state and camera. The scene is updated from the state on the
//! caller's thread (no OpenGL there); drawing and reading the pixels run on the renderer's
//! thread, which the caller waits for.
//!
//! ```no_run
//! use std::sync::Arc;
//! use twin_mj::{Data, Model, Renderer, View};
//!
//! let model = Arc::new(Model::from_file("scene.xml")?);
//! let mut data = Data::new(model.clone())?;
//! data.forward()?;
//! let mut renderer = Renderer::new(model.clone(), 640, 480)?;
//! let rgb = renderer.rgb(&mut data, View::Free)?; // 640 × 480 × 3 bytes
//! # Ok::<(), twin_mj::Error>(())
//! ```

use super::gl::GlThread;
use super::{Data, Model, ObjType, ffi, guarded};
use crate::error::{Error, Result};
use mujoco_sys as sys;
use std::sync::Arc;

/// The camera a frame is seen from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// The model's camera of this id (`mjCAMERA_FIXED`), with its `fovy`.
    Camera(usize),
    /// MuJoCo's default free camera of the model (`mjv_defaultFreeCamera`: looking at the
    /// model's centre from its `<visual><global>` azimuth and elevation).
    Free,
}

/// What a pixel of a segmentation image shows: the object MuJoCo drew there (a geom, or a
/// site, tendon or flex when the scene shows those).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Segment {
    /// MuJoCo's object type (`mjtObj`, e.g. 5 for a geom); see [`ObjType::from_raw`].
    pub objtype: i32,
    /// The object's id.
    pub objid: i32,
}

impl Segment {
    /// The geom's id when the pixel shows a geom.
    pub fn geom(self) -> Option<usize> {
        (ObjType::from_raw(self.objtype) == Some(ObjType::Geom)).then_some(self.objid as usize)
    }
}

/// An offscreen renderer of one model at one image size.
pub struct Renderer {
    model: Arc<Model>,
    /// The thread owning the OpenGL context; dropped after [`Renderer::drop`] has freed
    /// MuJoCo's render context on it.
    gl: GlThread,
    frame: FrameBuffers,
    option: Box<sys::mjvOption>,
    width: u32,
    height: u32,
}

/// MuJoCo's scene and render context and the bottom-up scratch rows read from OpenGL: what a
/// frame's job on the [`GlThread`] works on.
struct FrameBuffers {
    scene: Box<sys::mjvScene>,
    context: Box<sys::mjrContext>,
    rgb_scratch: Vec<u8>,
    depth_scratch: Vec<f32>,
}

// SAFETY: heap blocks owned by the renderer (the scene's and context's pointers lead to blocks
// MuJoCo made for them, and OpenGL object names of the renderer's own context), used by one
// thread at a time: through `&mut Renderer`, lent to the GlThread's job while the caller waits.
unsafe impl Send for FrameBuffers {}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("gl", &self.gl)
            .finish_non_exhaustive()
    }
}

/// Geoms a scene holds at most (MuJoCo's Python `Renderer` default).
const MAX_GEOM: i32 = 10_000;

impl Renderer {
    /// A renderer of `model` for `width × height` images (the offscreen buffer grows past the
    /// model's `<visual><global offwidth offheight>` when needed); MuJoCo's default scene
    /// flags (shadows and reflections on).
    ///
    /// # Errors
    /// [`Error::Render`] without an OpenGL library (naming what to install) or when OpenGL
    /// lacks what MuJoCo needs; [`Error::OutOfRange`] for an empty image.
    pub fn new(model: Arc<Model>, width: u32, height: u32) -> Result<Renderer> {
        Renderer::with_samples(model, width, height, None)
    }

    /// As [`Renderer::new`], with `samples` multisamples per pixel for antialiasing instead of
    /// the model's `<visual><quality offsamples>` (MuJoCo's default 4; 0 turns antialiasing off:
    /// on a CPU renderer about three times faster, with stair-stepped edges).
    ///
    /// # Errors
    /// As [`Renderer::new`].
    pub fn with_samples(model: Arc<Model>, width: u32, height: u32, samples: Option<u32>) -> Result<Renderer> {
        super::init()?;
        if width == 0 || height == 0 || width > 16_384 || height > 16_384 {
            return Err(Error::OutOfRange {
                what: "rendered image".into(),
                message: format!("{width}×{height} pixels: give a width and height from 1 to 16384"),
            });
        }
        let gl = GlThread::new()?;
        // SAFETY: all-zero bytes are a valid mjvScene/mjrContext/mjvOption (integers, floats,
        // null pointers); each is then set by MuJoCo's default/make functions below.
        let (mut scene, context, mut option) = unsafe {
            (
                Box::new(std::mem::zeroed::<sys::mjvScene>()),
                Box::new(std::mem::zeroed::<sys::mjrContext>()),
                Box::new(std::mem::zeroed::<sys::mjvOption>()),
            )
        };
        // SAFETY: a valid option struct to fill.
        unsafe { sys::mjv_defaultOption(&mut *option) };
        let samples = samples.map_or(-1, |s| s.min(64) as i32);
        let made = guarded("mjv_makeScene", |e, n| {
            // SAFETY: a live model and a scene struct to fill; errors are caught by the shim.
            unsafe { ffi::twin_render_make_scene(model.as_ptr(), &mut *scene, MAX_GEOM, e, n) }
        });
        // From here on Drop frees what was made (a zeroed context or scene is freed as empty).
        let mut renderer = Renderer {
            model,
            gl,
            frame: FrameBuffers { scene, context, rgb_scratch: Vec::new(), depth_scratch: Vec::new() },
            option,
            width,
            height,
        };
        let made = made.and_then(|()| {
            let (model, frame) = (&*renderer.model, &mut renderer.frame);
            renderer
                .gl
                .run(move || {
                    guarded("mjr_makeContext", |e, n| {
                        // SAFETY: the GlThread's context is current on this thread; a live model
                        // and a context struct to fill; errors are caught by the shim.
                        unsafe {
                            ffi::twin_render_make_context(
                                model.as_ptr(),
                                &mut *frame.context,
                                width as i32,
                                height as i32,
                                samples,
                                e,
                                n,
                            )
                        }
                    })
                })
                .and_then(|made| made)
        });
        made.map_err(|e| Error::Render { message: format!("MuJoCo's renderer could not start: {e}") })?;
        Ok(renderer)
    }

    /// Image width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The OpenGL backend, e.g. `EGL (device platform)`.
    pub fn backend(&self) -> String {
        self.gl.describe().to_string()
    }

    /// Turns MuJoCo's shadows and reflections on or off (both on by default, as in MuJoCo).
    pub fn set_shadows_and_reflections(&mut self, shadows: bool, reflections: bool) {
        self.frame.scene.flags[sys::mjtRndFlag__mjRND_SHADOW as usize] = u8::from(shadows);
        self.frame.scene.flags[sys::mjtRndFlag__mjRND_REFLECTION as usize] = u8::from(reflections);
    }

    /// Shows or hides geoms of MuJoCo group `group` (0–5; MuJoCo shows 0–2 by default).
    pub fn set_geom_group(&mut self, group: usize, visible: bool) {
        if let Some(g) = self.option.geomgroup.get_mut(group) {
            *g = u8::from(visible);
        }
    }

    /// The colour image of `data`'s state (its last forward pass) seen from `view`: RGB, 3
    /// bytes a pixel, top row first.
    ///
    /// # Errors
    /// As [`Renderer::depth`].
    pub fn rgb(&mut self, data: &mut Data, view: View) -> Result<Vec<u8>> {
        self.draw(data, view, false, true, false)?;
        Ok(flip_rows(&self.frame.rgb_scratch, 3 * self.width as usize))
    }

    /// The depth image of `data`'s state seen from `view`: metres along the optical axis,
    /// top row first; pixels with nothing drawn read the far plane (`<visual><map zfar>` ×
    /// the model's extent). MuJoCo's linearisation of its reversed depth buffer, as its
    /// Python `Renderer`.
    ///
    /// # Errors
    /// [`Error::Size`] for a `data` of a model with other geoms, meshes or cameras than the
    /// renderer's; [`Error::OutOfRange`] for a camera id the model lacks; [`Error::Render`]
    /// when OpenGL or MuJoCo fails.
    pub fn depth(&mut self, data: &mut Data, view: View) -> Result<Vec<f32>> {
        self.draw(data, view, true, false, true)?;
        let (near, far) = self.clip_planes();
        // MuJoCo's Python Renderer, in f64 from f32 planes: depth = d / (x + c).
        let (near, far) = (f64::from(near), f64::from(far));
        let c = 0.5 * (far + near) / (far - near) - 0.5;
        let d = far * near / (far - near);
        let linear: Vec<f32> = self.frame.depth_scratch.iter().map(|&x| (d / (f64::from(x) + c)) as f32).collect();
        Ok(flip_rows(&linear, self.width as usize))
    }

    /// The near and far clip planes, metres (`<visual><map znear zfar>` × the model's extent).
    pub fn clip_planes(&self) -> (f32, f32) {
        let m = self.model.raw();
        let extent = m.stat.extent as f32;
        (m.vis.map.znear * extent, m.vis.map.zfar * extent)
    }

    /// The segmentation image of `data`'s state seen from `view`: per pixel, the object drawn
    /// there (`None`: background), top row first. MuJoCo's `mjRND_SEGMENT` and
    /// `mjRND_IDCOLOR` flags, decoded as its Python `Renderer` does.
    ///
    /// # Errors
    /// As [`Renderer::depth`].
    pub fn segmentation(&mut self, data: &mut Data, view: View) -> Result<Vec<Option<Segment>>> {
        self.draw(data, view, true, true, false)?;
        // Colour value = segid + 1 (0: background) → the scene geom's object.
        let ngeom = self.frame.scene.ngeom.max(0) as usize;
        let mut by_segid = vec![None; ngeom + 2];
        if ngeom > 0 {
            // SAFETY: `geoms` holds `ngeom` initialised entries after mjv_updateScene.
            let geoms = unsafe { std::slice::from_raw_parts(self.frame.scene.geoms, ngeom) };
            for g in geoms.iter().filter(|g| g.segid >= 0 && (g.segid as usize) < ngeom + 1) {
                by_segid[g.segid as usize + 1] = Some(Segment { objtype: g.objtype, objid: g.objid });
            }
        }
        let labels: Vec<Option<Segment>> = self
            .frame
            .rgb_scratch
            .chunks_exact(3)
            .map(|p| {
                let v = usize::from(p[0]) | usize::from(p[1]) << 8 | usize::from(p[2]) << 16;
                by_segid.get(v).copied().flatten()
            })
            .collect();
        Ok(flip_rows(&labels, self.width as usize))
    }

    /// Renders one frame into the scratch buffers (bottom-up), with the segmentation flags on
    /// when `segment`.
    fn draw(&mut self, data: &mut Data, view: View, segment: bool, rgb: bool, depth: bool) -> Result<()> {
        let (a, b) = (self.model.raw(), data.model().raw());
        let layout = |m: &sys::mjModel| (m.ngeom, m.nmesh, m.ntex, m.nhfield, m.nskin, m.nflex, m.ncam, m.nmat);
        if layout(a) != layout(b) {
            return Err(Error::Size {
                what: "geoms of the rendered state's model",
                expected: a.ngeom as usize,
                got: b.ngeom as usize,
            });
        }
        let mut camera = sys::mjvCamera {
            type_: sys::mjtCamera__mjCAMERA_FREE as i32,
            fixedcamid: -1,
            trackbodyid: -1,
            lookat: [0.0; 3],
            distance: 0.0,
            azimuth: 0.0,
            elevation: 0.0,
            orthographic: 0,
        };
        match view {
            View::Camera(id) if id < self.model.ncam() => {
                camera.type_ = sys::mjtCamera__mjCAMERA_FIXED as i32;
                camera.fixedcamid = id as i32;
            }
            View::Camera(id) => {
                return Err(Error::OutOfRange {
                    what: "rendered camera".into(),
                    message: format!("camera id {id}: the model has {} cameras", self.model.ncam()),
                });
            }
            // SAFETY: a live model and a camera struct to fill.
            View::Free => unsafe { sys::mjv_defaultFreeCamera(self.model.as_ptr(), &mut camera) },
        }
        let n = self.width as usize * self.height as usize;
        let frame = &mut self.frame;
        frame.rgb_scratch.resize(if rgb { 3 * n } else { 0 }, 0);
        frame.depth_scratch.resize(if depth { n } else { 0 }, 0.0);
        let saved = frame.scene.flags;
        if segment {
            frame.scene.flags[sys::mjtRndFlag__mjRND_SEGMENT as usize] = 1;
            frame.scene.flags[sys::mjtRndFlag__mjRND_IDCOLOR as usize] = 1;
        }
        let (m, d) = data.raw_parts();
        let option = &*self.option;
        let updated = guarded("mjv_updateScene", |e, n| {
            // SAFETY: a live model/data pair of the renderer's layout (checked above), valid
            // option/camera/scene structs; errors are caught by the shim. No OpenGL call.
            unsafe { ffi::twin_render_update_scene(m, d, option, &mut camera, &mut *frame.scene, e, n) }
        });
        let (w, h) = (self.width as i32, self.height as i32);
        let drawn = updated.and_then(|()| {
            let buffers = &mut *frame;
            self.gl
                .run(move || {
                    let rgb_ptr = if rgb { buffers.rgb_scratch.as_mut_ptr() } else { std::ptr::null_mut() };
                    let depth_ptr = if depth { buffers.depth_scratch.as_mut_ptr() } else { std::ptr::null_mut() };
                    let (scene, context) = (&mut *buffers.scene, &*buffers.context);
                    guarded("mjr_render", |e, n| {
                        // SAFETY: the GlThread's context is current on this thread; the buffers
                        // hold w·h·3 bytes and w·h floats (or are null when not read); the
                        // viewport fits the offscreen buffer (grown to it in new()).
                        unsafe { ffi::twin_render_read(w, h, scene, context, rgb_ptr, depth_ptr, e, n) }
                    })
                })
                .and_then(|drawn| drawn)
        });
        frame.scene.flags = saved;
        drawn.map_err(|e| Error::Render { message: e.to_string() })
    }
}

impl Drop for Renderer {
    /// Frees MuJoCo's render context on the GlThread (`mjr_freeContext` deletes OpenGL objects:
    /// its context must be current), then the scene; the GlThread, dropped next, destroys the
    /// OpenGL context and is joined.
    fn drop(&mut self) {
        let frame = &mut self.frame;
        // SAFETY: a context made by mjr_makeContext (or zeroed, or defaulted by
        // mjr_defaultContext, which free as empty), freed once, on the thread where its OpenGL
        // context is current.
        let _ = self.gl.run(move || unsafe { sys::mjr_freeContext(&mut *frame.context) });
        // SAFETY: a scene made by mjv_makeScene (or zeroed, which mjv_freeScene accepts), freed once.
        unsafe { sys::mjv_freeScene(&mut *self.frame.scene) };
    }
}

/// `data` (rows of `row_len` items, bottom row first) with its rows in top-down order.
fn flip_rows<T: Copy>(data: &[T], row_len: usize) -> Vec<T> {
    let mut out = Vec::with_capacity(data.len());
    for row in data.chunks_exact(row_len).rev() {
        out.extend_from_slice(row);
    }
    out
}
