//! An offscreen OpenGL context for MuJoCo's renderer ([`super::Renderer`]), headless: EGL
//! (the device platform, else Mesa's surfaceless platform; a GPU driver's or Mesa's llvmpipe),
//! else OSMesa. Both libraries are loaded at run time (`dlopen`), so twin starts on a machine
//! without them; there, making a context is an [`Error::Render`] that names what to install,
//! and the ray-cast sensors (depth cameras, LiDARs) work as before.
//!
//! `TWIN_GL=egl` or `TWIN_GL=osmesa` picks one backend (default: EGL, then OSMesa);
//! `TWIN_EGL_LIBRARY` and `TWIN_OSMESA_LIBRARY` name the library files to load instead of
//! `libEGL.so.1` and `libOSMesa.so.8`/`.6`. The library is loaded with `RTLD_GLOBAL`: MuJoCo
//! finds its OpenGL functions through `eglGetProcAddress`/`OSMesaGetProcAddress` in the global
//! namespace, and it is never unloaded. One process uses one backend (the first that worked).
//!
//! A context lives on a [`GlThread`] of its own for its whole life: made there, current there
//! from the start, every OpenGL call of its renderer run there ([`GlThread::run`]), destroyed
//! there, and the thread joined when the `GlThread` drops, after `eglReleaseThread`. No other
//! thread touches EGL's per-thread state (loading runs on a short thread of its own too). This
//! is what keeps the process's exit sound: libglvnd's `libEGL` frees, in its destructor at
//! exit (`__eglFini`), the per-thread state of every thread that ever called EGL and has not
//! released it, while a thread that ends frees its own in a `pthread` key destructor; a thread
//! still ending when `main` returns (a `rayon` pool's are not joined when the pool drops) made
//! both free the same block ("corrupted size vs. prev_size in fastbins", "double free" at exit).
//! A thread that releases its state and is joined before exit cannot race that destructor.

use crate::error::{Error, Result};
use std::ffi::{CStr, CString, c_char, c_int, c_uint, c_void};
use std::sync::{Mutex, OnceLock, mpsc};

/// What to install when no OpenGL library loads.
const INSTALL: &str = "install EGL with Mesa's software renderer (Debian/Ubuntu: `apt-get install libegl1 \
                       libgl1-mesa-dri`), or OSMesa (`apt-get install libosmesa6`), or a GPU driver's EGL; \
                       depth cameras and LiDARs do not need it (they are ray-cast)";

/// Which OpenGL library a context comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GlBackend {
    /// EGL (the device platform, else Mesa's surfaceless platform), no window or surface.
    Egl,
    /// Mesa's off-screen rasterizer, rendering into a buffer of its own.
    OsMesa,
}

type EglDisplay = *mut c_void;
type EglConfig = *mut c_void;
type EglContext = *mut c_void;
type EglDevice = *mut c_void;
type EglBoolean = c_uint;
type EglInt = i32;

const EGL_NONE: EglInt = 0x3038;
const EGL_RED_SIZE: EglInt = 0x3024;
const EGL_GREEN_SIZE: EglInt = 0x3023;
const EGL_BLUE_SIZE: EglInt = 0x3022;
const EGL_ALPHA_SIZE: EglInt = 0x3021;
const EGL_DEPTH_SIZE: EglInt = 0x3025;
const EGL_STENCIL_SIZE: EglInt = 0x3026;
const EGL_COLOR_BUFFER_TYPE: EglInt = 0x303F;
const EGL_RGB_BUFFER: EglInt = 0x308E;
const EGL_SURFACE_TYPE: EglInt = 0x3033;
const EGL_PBUFFER_BIT: EglInt = 0x0001;
const EGL_RENDERABLE_TYPE: EglInt = 0x3040;
const EGL_OPENGL_BIT: EglInt = 0x0008;
const EGL_OPENGL_API: c_uint = 0x30A2;
const EGL_EXTENSIONS: EglInt = 0x3055;
const EGL_PLATFORM_DEVICE_EXT: c_uint = 0x313F;
const EGL_PLATFORM_SURFACELESS_MESA: c_uint = 0x31DD;

/// The EGL entry points twin calls per context, and the display and configuration found at
/// loading (through EGL 1.4 core, `EGL_EXT_platform_base` and `EGL_EXT_device_enumeration`).
struct Egl {
    get_error: unsafe extern "C" fn() -> EglInt,
    bind_api: unsafe extern "C" fn(c_uint) -> EglBoolean,
    create_context: unsafe extern "C" fn(EglDisplay, EglConfig, EglContext, *const EglInt) -> EglContext,
    destroy_context: unsafe extern "C" fn(EglDisplay, EglContext) -> EglBoolean,
    make_current: unsafe extern "C" fn(EglDisplay, *mut c_void, *mut c_void, EglContext) -> EglBoolean,
    release_thread: unsafe extern "C" fn() -> EglBoolean,
    /// The display every context of the process is made on, and the platform it came from.
    display: EglDisplay,
    config: EglConfig,
    platform: &'static str,
}

/// The OSMesa entry points twin calls.
struct OsMesa {
    create_context_ext: unsafe extern "C" fn(c_uint, c_int, c_int, c_int, *mut c_void) -> *mut c_void,
    make_current: unsafe extern "C" fn(*mut c_void, *mut c_void, c_uint, c_int, c_int) -> u8,
    destroy_context: unsafe extern "C" fn(*mut c_void),
}

const OSMESA_RGBA: c_uint = 0x1908;
const GL_UNSIGNED_BYTE: c_uint = 0x1401;

enum Loaded {
    Egl(Egl),
    OsMesa(OsMesa),
}

// SAFETY: the loaded tables hold function pointers and EGL handles (display, config) that EGL
// documents as usable from any thread; they are written once and only read afterwards.
unsafe impl Send for Loaded {}
// SAFETY: as above: read-only after loading.
unsafe impl Sync for Loaded {}

/// The backend of the process: loaded on first use, then kept (MuJoCo binds its OpenGL
/// function loader to it).
fn loaded() -> std::result::Result<&'static Loaded, String> {
    static LOADED: OnceLock<std::result::Result<Loaded, String>> = OnceLock::new();
    LOADED
        .get_or_init(|| {
            // On a thread of its own that releases EGL's per-thread state and is joined (see the
            // module docs): the caller may be a pool's thread that is never joined.
            std::thread::scope(|scope| {
                scope
                    .spawn(|| {
                        let loaded = load();
                        if let Ok(Loaded::Egl(egl)) = &loaded {
                            egl.release_thread();
                        }
                        loaded
                    })
                    .join()
                    .unwrap_or_else(|_| Err("loading the OpenGL library panicked".into()))
            })
        })
        .as_ref()
        .map_err(Clone::clone)
}

impl Egl {
    /// `eglReleaseThread`: unbinds the calling thread's context and frees EGL's state of the
    /// thread, so that nothing of this thread is left for libEGL's destructor at exit.
    fn release_thread(&self) {
        // SAFETY: no preconditions; a thread without EGL state is a no-op.
        unsafe { (self.release_thread)() };
    }
}

fn load() -> std::result::Result<Loaded, String> {
    let wanted = std::env::var("TWIN_GL").unwrap_or_default().to_ascii_lowercase();
    let mut tried = Vec::new();
    if wanted.is_empty() || wanted == "egl" {
        match load_egl() {
            Ok(egl) => return Ok(Loaded::Egl(egl)),
            Err(e) => tried.push(format!("EGL: {e}")),
        }
    }
    if wanted.is_empty() || wanted == "osmesa" {
        match load_osmesa() {
            Ok(osmesa) => return Ok(Loaded::OsMesa(osmesa)),
            Err(e) => tried.push(format!("OSMesa: {e}")),
        }
    }
    if tried.is_empty() {
        return Err(format!("TWIN_GL={wanted} is not an OpenGL backend twin knows: give egl or osmesa (or unset it)"));
    }
    Err(format!("no OpenGL context for rendering cameras ({}): {INSTALL}", tried.join("; ")))
}

/// `dlopen`s the first of `names` that loads, globally (MuJoCo looks its loader up there).
fn open_library(names: &[String]) -> std::result::Result<*mut c_void, String> {
    let mut why = Vec::new();
    for name in names {
        let c = CString::new(name.as_str()).map_err(|_| format!("library name {name:?} has a NUL byte"))?;
        // SAFETY: dlopen with a NUL-terminated name; the handle is never closed (MuJoCo keeps
        // function pointers into the library for the life of the process).
        let handle = unsafe { libc::dlopen(c.as_ptr(), libc::RTLD_NOW | libc::RTLD_GLOBAL) };
        if !handle.is_null() {
            return Ok(handle);
        }
        // SAFETY: dlerror returns a NUL-terminated string owned by libc, or null.
        let e = unsafe { libc::dlerror() };
        why.push(if e.is_null() {
            format!("{name} not found")
        } else {
            // SAFETY: non-null: a NUL-terminated message.
            unsafe { CStr::from_ptr(e) }.to_string_lossy().into_owned()
        });
    }
    Err(why.join(", "))
}

/// The library names to try: the override variable's value, else `defaults`.
fn library_names(var: &str, defaults: &[&str]) -> Vec<String> {
    match std::env::var(var) {
        Ok(v) if !v.is_empty() => vec![v],
        _ => defaults.iter().map(|s| s.to_string()).collect(),
    }
}

/// Looks up `name` in `handle` as a function of type `F`.
///
/// # Safety
/// `F` must be the C signature of the symbol.
unsafe fn symbol<F: Copy>(handle: *mut c_void, name: &str) -> std::result::Result<F, String> {
    let c = CString::new(name).expect("symbol names have no NUL");
    // SAFETY: dlsym on a live handle with a NUL-terminated name.
    let p = unsafe { libc::dlsym(handle, c.as_ptr()) };
    if p.is_null() {
        return Err(format!("the library has no {name}"));
    }
    assert_eq!(std::mem::size_of::<F>(), std::mem::size_of::<*mut c_void>());
    // SAFETY: a non-null symbol address reinterpreted as the function type the caller names.
    Ok(unsafe { std::mem::transmute_copy::<*mut c_void, F>(&p) })
}

fn load_egl() -> std::result::Result<Egl, String> {
    let handle = open_library(&library_names("TWIN_EGL_LIBRARY", &["libEGL.so.1", "libEGL.so"]))?;
    // SAFETY: each type below is the EGL 1.4 C signature of its symbol.
    let (get_proc, get_error, query_string, initialize, choose_config, bind_api) = unsafe {
        (
            symbol::<unsafe extern "C" fn(*const c_char) -> *mut c_void>(handle, "eglGetProcAddress")?,
            symbol::<unsafe extern "C" fn() -> EglInt>(handle, "eglGetError")?,
            symbol::<unsafe extern "C" fn(EglDisplay, EglInt) -> *const c_char>(handle, "eglQueryString")?,
            symbol::<unsafe extern "C" fn(EglDisplay, *mut EglInt, *mut EglInt) -> EglBoolean>(
                handle,
                "eglInitialize",
            )?,
            symbol::<unsafe extern "C" fn(EglDisplay, *const EglInt, *mut EglConfig, EglInt, *mut EglInt) -> EglBoolean>(
                handle,
                "eglChooseConfig",
            )?,
            symbol::<unsafe extern "C" fn(c_uint) -> EglBoolean>(handle, "eglBindAPI")?,
        )
    };
    // SAFETY: as above.
    let (create_context, destroy_context, make_current, release_thread) = unsafe {
        (
            symbol::<unsafe extern "C" fn(EglDisplay, EglConfig, EglContext, *const EglInt) -> EglContext>(
                handle,
                "eglCreateContext",
            )?,
            symbol::<unsafe extern "C" fn(EglDisplay, EglContext) -> EglBoolean>(handle, "eglDestroyContext")?,
            symbol::<unsafe extern "C" fn(EglDisplay, *mut c_void, *mut c_void, EglContext) -> EglBoolean>(
                handle,
                "eglMakeCurrent",
            )?,
            symbol::<unsafe extern "C" fn() -> EglBoolean>(handle, "eglReleaseThread")?,
        )
    };
    let ext = |name: &str| -> Option<*mut c_void> {
        let c = CString::new(name).ok()?;
        // SAFETY: eglGetProcAddress with a NUL-terminated name; null when unknown.
        let p = unsafe { get_proc(c.as_ptr()) };
        (!p.is_null()).then_some(p)
    };
    // SAFETY: EGL_NO_DISPLAY with EGL_EXTENSIONS gives the client extensions (or null).
    let client = unsafe { query_string(std::ptr::null_mut(), EGL_EXTENSIONS) };
    let client = if client.is_null() {
        String::new()
    } else {
        // SAFETY: non-null: a NUL-terminated string owned by EGL.
        unsafe { CStr::from_ptr(client) }.to_string_lossy().into_owned()
    };
    let has = |e: &str| client.split_whitespace().any(|x| x == e);
    let get_platform_display = ext("eglGetPlatformDisplayEXT").ok_or_else(|| {
        "the EGL library has no eglGetPlatformDisplayEXT (EGL_EXT_platform_base): a headless display needs it"
            .to_string()
    })?;
    // SAFETY: the EGL_EXT_platform_base signature.
    let get_platform_display: unsafe extern "C" fn(c_uint, *mut c_void, *const EglInt) -> EglDisplay =
        unsafe { std::mem::transmute(get_platform_display) };
    let init = |display: EglDisplay| -> bool {
        if display.is_null() {
            return false;
        }
        let (mut major, mut minor) = (0, 0);
        // SAFETY: a display from eglGetPlatformDisplayEXT; the version outputs are valid.
        unsafe { initialize(display, &mut major, &mut minor) != 0 }
    };
    let mut found: Option<(EglDisplay, &'static str)> = None;
    if has("EGL_EXT_platform_device")
        && let Some(query_devices) = ext("eglQueryDevicesEXT")
    {
        // SAFETY: the EGL_EXT_device_enumeration signature.
        let query_devices: unsafe extern "C" fn(EglInt, *mut EglDevice, *mut EglInt) -> EglBoolean =
            unsafe { std::mem::transmute(query_devices) };
        let mut devices = [std::ptr::null_mut(); 16];
        let mut n = 0;
        // SAFETY: room for 16 devices, the count written to `n`.
        if unsafe { query_devices(devices.len() as EglInt, devices.as_mut_ptr(), &mut n) } != 0 {
            for &device in &devices[..n.clamp(0, 16) as usize] {
                // SAFETY: a device handle from eglQueryDevicesEXT, no attributes.
                let display = unsafe { get_platform_display(EGL_PLATFORM_DEVICE_EXT, device, std::ptr::null()) };
                if init(display) {
                    found = Some((display, "device"));
                    break;
                }
            }
        }
    }
    if found.is_none() && has("EGL_MESA_platform_surfaceless") {
        // SAFETY: the surfaceless platform takes EGL_DEFAULT_DISPLAY (null) and no attributes.
        let display =
            unsafe { get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, std::ptr::null_mut(), std::ptr::null()) };
        if init(display) {
            found = Some((display, "surfaceless"));
        }
    }
    let Some((display, platform)) = found else {
        // SAFETY: no preconditions.
        let code = unsafe { get_error() };
        return Err(format!(
            "no EGL display on the device or surfaceless platform (client extensions: {client}; eglGetError \
             {code:#x})"
        ));
    };
    let attributes = [
        EGL_RED_SIZE,
        8,
        EGL_GREEN_SIZE,
        8,
        EGL_BLUE_SIZE,
        8,
        EGL_ALPHA_SIZE,
        8,
        EGL_DEPTH_SIZE,
        24,
        EGL_STENCIL_SIZE,
        8,
        EGL_COLOR_BUFFER_TYPE,
        EGL_RGB_BUFFER,
        EGL_SURFACE_TYPE,
        EGL_PBUFFER_BIT,
        EGL_RENDERABLE_TYPE,
        EGL_OPENGL_BIT,
        EGL_NONE,
    ];
    let mut config = std::ptr::null_mut();
    let mut n = 0;
    // SAFETY: an initialized display, a NONE-terminated attribute list, room for one config.
    let ok = unsafe { choose_config(display, attributes.as_ptr(), &mut config, 1, &mut n) };
    if ok == 0 || n < 1 {
        return Err(format!("the EGL {platform} display has no 8-bit RGBA, 24-bit depth OpenGL configuration"));
    }
    Ok(Egl {
        get_error,
        bind_api,
        create_context,
        destroy_context,
        make_current,
        release_thread,
        display,
        config,
        platform,
    })
}

fn load_osmesa() -> std::result::Result<OsMesa, String> {
    let handle =
        open_library(&library_names("TWIN_OSMESA_LIBRARY", &["libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so"]))?;
    // SAFETY: each type below is the OSMesa C signature of its symbol.
    unsafe {
        Ok(OsMesa {
            create_context_ext: symbol(handle, "OSMesaCreateContextExt")?,
            make_current: symbol(handle, "OSMesaMakeCurrent")?,
            destroy_context: symbol(handle, "OSMesaDestroyContext")?,
        })
    }
}

/// An OpenGL context for offscreen rendering, current on the [`GlThread`] that made it. MuJoCo
/// renders into its own framebuffer object, so the context needs no surface; OSMesa's gets a
/// small colour buffer of its own. Not `Send`: it never leaves its thread.
struct GlContext {
    context: *mut c_void,
    /// OSMesa's colour buffer (RGBA, `OSMESA_BUFFER` pixels); empty for EGL.
    buffer: Vec<u8>,
}

/// Side of OSMesa's default framebuffer: MuJoCo renders into its own offscreen buffer.
const OSMESA_BUFFER: usize = 16;

/// Serialises context creation: EGL's `eglBindAPI` is per thread, but Mesa's context creation
/// is not always safe to race.
static CREATE: Mutex<()> = Mutex::new(());

impl GlContext {
    /// A new context of the process's backend (loading it on first use), current on the calling
    /// thread.
    fn new_current() -> Result<GlContext> {
        let lib = loaded().map_err(|message| Error::Render { message })?;
        let _guard = CREATE.lock().unwrap_or_else(|e| e.into_inner());
        let mut context = match lib {
            Loaded::Egl(egl) => {
                // SAFETY: EGL_OPENGL_API is a valid API enum.
                if unsafe { (egl.bind_api)(EGL_OPENGL_API) } == 0 {
                    return Err(Error::Render {
                        message: format!("EGL ({} platform) has no desktop OpenGL API: {INSTALL}", egl.platform),
                    });
                }
                // SAFETY: display and config from loading; no shared context, no attributes.
                let context =
                    unsafe { (egl.create_context)(egl.display, egl.config, std::ptr::null_mut(), std::ptr::null()) };
                if context.is_null() {
                    // SAFETY: no preconditions.
                    let code = unsafe { (egl.get_error)() };
                    return Err(Error::Render {
                        message: format!(
                            "EGL ({} platform) could not create an OpenGL context (eglGetError {code:#x})",
                            egl.platform
                        ),
                    });
                }
                GlContext { context, buffer: Vec::new() }
            }
            Loaded::OsMesa(osmesa) => {
                // SAFETY: RGBA with 24-bit depth, 8-bit stencil, no accumulation, no sharing.
                let context = unsafe { (osmesa.create_context_ext)(OSMESA_RGBA, 24, 8, 0, std::ptr::null_mut()) };
                if context.is_null() {
                    return Err(Error::Render { message: "OSMesa could not create an OpenGL context".into() });
                }
                GlContext { context, buffer: vec![0; OSMESA_BUFFER * OSMESA_BUFFER * 4] }
            }
        };
        let ok = match lib {
            // SAFETY: a live context of this display, no surfaces (EGL_KHR_surfaceless_context).
            Loaded::Egl(egl) => unsafe {
                (egl.make_current)(egl.display, std::ptr::null_mut(), std::ptr::null_mut(), context.context) != 0
            },
            // SAFETY: a live context and its buffer of OSMESA_BUFFER² RGBA bytes, which lives as
            // long as the context (the Vec's heap block does not move with the struct).
            Loaded::OsMesa(osmesa) => unsafe {
                (osmesa.make_current)(
                    context.context,
                    context.buffer.as_mut_ptr().cast(),
                    GL_UNSIGNED_BYTE,
                    OSMESA_BUFFER as c_int,
                    OSMESA_BUFFER as c_int,
                ) != 0
            },
        };
        if ok {
            Ok(context)
        } else {
            // Dropping it unbinds nothing and destroys the context.
            Err(Error::Render { message: "could not make the new OpenGL context current".into() })
        }
    }
}

impl Drop for GlContext {
    /// Unbinds the context from its thread, then destroys it.
    fn drop(&mut self) {
        match loaded() {
            Ok(Loaded::Egl(egl)) => {
                // SAFETY: unbinding the calling thread's context (no surfaces, no context), then
                // destroying this context of this display, now current nowhere.
                unsafe {
                    (egl.make_current)(egl.display, std::ptr::null_mut(), std::ptr::null_mut(), std::ptr::null_mut());
                    (egl.destroy_context)(egl.display, self.context);
                }
            }
            // SAFETY: OSMesaMakeCurrent with no context and no buffer unbinds the thread's
            // context; then a context made by OSMesaCreateContextExt, destroyed once.
            Ok(Loaded::OsMesa(osmesa)) => unsafe {
                (osmesa.make_current)(std::ptr::null_mut(), std::ptr::null_mut(), 0, 0, 0);
                (osmesa.destroy_context)(self.context);
            },
            Err(_) => {}
        }
    }
}

/// A job for a [`GlThread`].
type Job = Box<dyn FnOnce() + Send + 'static>;

/// A thread that owns one OpenGL context for the context's whole life (see the module docs):
/// it makes the context and makes it current, runs the jobs given to [`GlThread::run`] one at
/// a time with it current, and when the `GlThread` drops it destroys the context, releases
/// EGL's state of the thread and is joined. A renderer's OpenGL calls (MuJoCo's `mjr_*`) all
/// go through its `GlThread`, whichever thread the renderer is used from.
pub struct GlThread {
    jobs: Option<mpsc::Sender<Job>>,
    thread: Option<std::thread::JoinHandle<()>>,
    backend: String,
}

impl std::fmt::Debug for GlThread {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GlThread").field("backend", &self.backend).finish()
    }
}

impl GlThread {
    /// Starts the thread and makes its context (loading the OpenGL library on first use).
    ///
    /// # Errors
    /// [`Error::Render`] when neither EGL nor OSMesa loads or gives a context (naming what to
    /// install), or when the thread can't be started.
    pub fn new() -> Result<GlThread> {
        let (jobs, queue) = mpsc::channel::<Job>();
        let (ready, started) = mpsc::sync_channel::<Result<String>>(1);
        let thread = std::thread::Builder::new()
            .name("twin-gl".into())
            .spawn(move || {
                match GlContext::new_current() {
                    Ok(context) => {
                        let _ = ready.send(Ok(describe()));
                        for job in queue {
                            // A job that panics has handed nothing back: its caller gets an
                            // error; the context stays for the jobs after it and the teardown.
                            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(job));
                        }
                        drop(context);
                    }
                    Err(e) => {
                        let _ = ready.send(Err(e));
                    }
                }
                if let Ok(Loaded::Egl(egl)) = loaded() {
                    egl.release_thread();
                }
            })
            .map_err(|e| Error::Render { message: format!("can't start a rendering thread: {e}") })?;
        let started = started.recv();
        let mut gl = GlThread { jobs: Some(jobs), thread: Some(thread), backend: String::new() };
        match started {
            Ok(Ok(backend)) => {
                gl.backend = backend;
                Ok(gl)
            }
            // Dropping `gl` joins the thread, which has ended.
            Ok(Err(e)) => Err(e),
            Err(_) => Err(Error::Render { message: "the rendering thread ended before making its context".into() }),
        }
    }

    /// A short description of the backend, e.g. `EGL (device platform)`.
    pub fn describe(&self) -> &str {
        &self.backend
    }

    /// Runs `job` on the thread, with its context current, and waits for its result.
    ///
    /// # Errors
    /// [`Error::Render`] when the job panicked or the thread is gone.
    pub fn run<R: Send>(&self, job: impl FnOnce() -> R + Send) -> Result<R> {
        let gone = || Error::Render {
            message: "the rendering job did not finish (it panicked, or the rendering thread is gone)".into(),
        };
        let (tx, rx) = mpsc::sync_channel::<R>(1);
        let boxed: Box<dyn FnOnce() + Send + '_> = Box::new(move || {
            let _ = tx.send(job());
        });
        // SAFETY: only the lifetime is erased (same layout). The job's borrows outlive its use:
        // this function returns only after `rx` has a result (the job ran) or is disconnected,
        // which happens when `tx` drops, and `tx` drops after `job` has run or unwound, or with
        // the whole job unrun (the queue dropped); a job that can't be queued comes back in the
        // send error and is dropped here.
        let boxed: Job = unsafe { std::mem::transmute::<Box<dyn FnOnce() + Send + '_>, Job>(boxed) };
        self.jobs.as_ref().ok_or_else(gone)?.send(boxed).map_err(|_| gone())?;
        rx.recv().map_err(|_| gone())
    }
}

impl Drop for GlThread {
    /// Ends the thread (it destroys its context and releases EGL's thread state) and joins it.
    fn drop(&mut self) {
        drop(self.jobs.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// A short description of the process's backend, e.g. `EGL (device platform)`.
fn describe() -> String {
    match loaded() {
        Ok(Loaded::Egl(egl)) => format!("EGL ({} platform)", egl.platform),
        Ok(Loaded::OsMesa(_)) => "OSMesa".into(),
        Err(e) => e,
    }
}

/// Whether an OpenGL backend loads on this machine, and if not, why (the text of the
/// [`Error::Render`] a renderer would give).
pub fn gl_available() -> std::result::Result<GlBackend, String> {
    loaded().map(|l| match l {
        Loaded::Egl(_) => GlBackend::Egl,
        Loaded::OsMesa(_) => GlBackend::OsMesa,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every job of a GlThread runs on that one thread (never the caller's), which keeps its
    /// context current; a job that panics is an error for its caller, not the end of the thread.
    #[test]
    fn jobs_run_on_the_context_thread_and_a_panic_is_an_error() {
        let gl = GlThread::new().expect("an OpenGL context (EGL or OSMesa; see the module docs)");
        let caller = std::thread::current().id();
        let (first, name) =
            gl.run(|| (std::thread::current().id(), std::thread::current().name().map(String::from))).unwrap();
        let second = gl.run(|| std::thread::current().id()).unwrap();
        assert_eq!(first, second);
        assert_ne!(first, caller);
        assert_eq!(name.as_deref(), Some("twin-gl"));
        let mut borrowed = vec![1, 2, 3];
        gl.run(|| borrowed.push(4)).unwrap();
        assert_eq!(borrowed, [1, 2, 3, 4]);
        let panicked = gl.run(|| -> u8 { panic!("a job that fails") });
        assert!(
            matches!(&panicked, Err(Error::Render { message }) if message.contains("rendering job did not finish")),
            "{panicked:?}"
        );
        assert_eq!(gl.run(|| 7).unwrap(), 7);
    }
}
