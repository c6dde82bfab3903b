//! `sylva view` (feature `window`): the renderer in a window, flown with
//! keyboard and mouse. Each frame is a flight's frame ([`super::fly::Flight`]:
//! the same selection, loading and ray casting as `sylva fly`) from the
//! camera the controls ([`controls`]) move, copied to the window
//! ([`present`]); the window's title shows the frame rate, the tiles and
//! the height above the surface. A frame never waits for tiles: they load
//! in the background, their nearest loaded ancestors drawn meanwhile.
//!
//! Keys: W/S or ↑/↓ forward and back, A/D sideways, Q/E down and up, ←/→
//! turn, R/F pitch, Shift faster, the mouse wheel sets the speed, a left
//! drag looks around; L switches the sun (and its shadow rays) on and off,
//! T switches between the exact traversal and the linear march, P saves
//! the frame as PNG, Esc quits.

pub mod controls;
pub mod input;
pub mod present;

use super::envelope::HeightEnvelope;
use super::fly::{self, FlyError, FlyOptions, FrameRecord, Motion, Shot};
use super::globe::Geodetic;
use super::path::{CameraPath, Sun};
use super::raycast::Traversal;
use super::render::gpu::{Gpu, GpuError};
use super::render::{Readback, Renderer};
use super::source::TileSource;
use super::tile::TileData;
use crate::grid::BBox;
use crate::lod::predict::MotionLimits;
use controls::{Controls, Pose};
use glam::DVec3;
use input::Input;
use present::{PresentError, Presenter};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

/// How to view.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// How frames are rendered and tiles chosen; `size` is the window's
    /// first size (its `frames`, `out_dir`, `write_frames` and `hold_ms`
    /// are not used).
    pub render: FlyOptions,
    /// Where the eye starts (`None`: [`default_start`]).
    pub start: Option<Pose>,
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
    /// The sun seen from the start, if it is on.
    pub sun: Option<Sun>,
    /// GPU tile cache budget, bytes.
    pub gpu_budget_bytes: usize,
    /// Close after this many frames (scripted runs).
    pub exit_after: Option<usize>,
    /// Where the frames' statistics (`stats.csv`) go on closing, with the
    /// last frame of a scripted run, and where `P` saves frames (default:
    /// the current directory).
    pub out_dir: Option<PathBuf>,
    /// An earlier run's outputs in `out_dir` (found before the view
    /// opened, with `--overwrite`), removed on closing.
    pub earlier: Vec<PathBuf>,
}

/// Why the viewer stopped.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// No window system.
    #[error("no window could be opened ({0}); `sylva view` needs a display (X11 or Wayland)")]
    Window(String),
    /// No GPU.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// The GPU has not the memory for the tile cache.
    #[error(transparent)]
    Alloc(#[from] crate::client::render::gpu::AllocError),
    /// The window could not show frames.
    #[error(transparent)]
    Present(#[from] PresentError),
    /// A frame failed.
    #[error(transparent)]
    Fly(#[from] FlyError),
    /// The window system failed while the view ran (an X server gone).
    #[error("the window system failed ({why}){kept}")]
    Lost {
        /// What it said.
        why: String,
        /// Where the statistics are, if anywhere.
        kept: String,
    },
    /// Ctrl-C or SIGTERM closed the view (its statistics written).
    #[error("closed by signal {signal}{kept}")]
    Interrupted {
        /// The signal's number.
        signal: i32,
        /// Where the statistics are, if anywhere.
        kept: String,
        /// Every frame's statistics.
        records: Vec<FrameRecord>,
    },
}

/// The eye of a view given no start: above the middle of the source's
/// region, this high above its highest surface, looking north and down.
pub const START_ABOVE_M: f64 = 1500.0;
/// ... and down by this much, degrees.
pub const START_PITCH_DEG: f64 = -25.0;

/// The field of view of a view without a path, degrees.
pub const FOV_DEG: f64 = 60.0;
/// The sun of a view without a path: south-east, 35° high.
pub const SUN: Sun = Sun { azimuth_deg: 135.0, elevation_deg: 35.0 };

/// Where a view starting on `path` begins: its first keyframe.
pub fn path_start(path: &CameraPath) -> Pose {
    let k = path.key[0];
    Pose { eye: Geodetic::new(k.lon, k.lat, k.height_m), heading_deg: k.heading_deg, pitch_deg: k.pitch_deg }
}

/// Where a view of the region `b` without a start begins
/// ([`START_ABOVE_M`] above the highest surface its coarse tiles'
/// `envelope` knows).
pub fn default_start(b: &BBox, envelope: &HeightEnvelope) -> Pose {
    let top_m = envelope.range(&b.sector()).map_or(0.0, |(_, hi)| hi);
    // The middle of a box past 180° said on the globe.
    let lon = (0.5 * (b.west + b.east) + 180.0).rem_euclid(360.0) - 180.0;
    let eye = Geodetic::new(lon, 0.5 * (b.south + b.north), top_m + START_ABOVE_M);
    Pose { eye, heading_deg: 0.0, pitch_deg: START_PITCH_DEG }
}

/// Opens a window over `source` and flies until it is closed (or Ctrl-C
/// or SIGTERM, watched by `interrupt` since before the view was set up,
/// closes it: [`ViewError::Interrupted`], after the statistics are
/// written); returns every frame's statistics.
pub fn run(
    source: Arc<dyn TileSource>,
    options: ViewOptions,
    interrupt: crate::interrupt::Interrupt,
) -> Result<Vec<FrameRecord>, ViewError> {
    let event_loop = EventLoop::new().map_err(window_error)?;
    let mut app = App { source, options, state: None, records: Vec::new(), error: None, interrupt };
    if let Err(why) = run_loop(event_loop, &mut app) {
        let kept = match app.records.is_empty() {
            true => String::new(),
            false => write_outputs(&app)?,
        };
        return Err(ViewError::Lost { why, kept });
    }
    if let Some(error) = app.error {
        return Err(error);
    }
    // Closed by a signal before its first frame: nothing to write, and an
    // earlier run's outputs stay.
    let kept = match app.records.is_empty() && app.interrupt.came().is_some() {
        true => String::new(),
        false => write_outputs(&app)?,
    };
    match app.interrupt.came() {
        Some(signal) => Err(ViewError::Interrupted { signal, kept, records: app.records }),
        None => Ok(app.records),
    }
}

/// Replaces an earlier run's outputs (not frames this run saved) with the
/// statistics: "; its stats.csv is in DIR", or nothing without a directory.
fn write_outputs(app: &App) -> Result<String, ViewError> {
    let Some(dir) = &app.options.out_dir else { return Ok(String::new()) };
    fly::remove_outputs(&app.options.earlier)?;
    fly::write_stats(dir, &app.records)?;
    Ok(format!("; its stats.csv is in {}", dir.display()))
}

/// Runs the event loop. The window system's library panics where the
/// display goes away (winit on a lost X connection): such a panic, on this
/// thread and from inside that library, is an error here, said once, not a
/// crash; any other panic stays one.
fn run_loop(event_loop: EventLoop<()>, app: &mut App) -> Result<(), String> {
    let this = std::thread::current().id();
    let lost = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let others: Arc<dyn Fn(&std::panic::PanicHookInfo) + Send + Sync> = Arc::from(std::panic::take_hook());
    let (chained, seen) = (others.clone(), lost.clone());
    std::panic::set_hook(Box::new(move |info| {
        let file = info.location().map_or("", |l| l.file());
        match std::thread::current().id() == this && WINDOW_SYSTEM.iter().any(|lib| file.contains(lib)) {
            true => seen.store(true, std::sync::atomic::Ordering::SeqCst),
            false => chained(info),
        }
    }));
    let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| event_loop.run_app(app)));
    std::panic::set_hook(Box::new(move |info| others(info)));
    match ran {
        Ok(result) => result.map_err(|e| without_location(&e.to_string()).to_string()),
        Err(panic) if lost.load(std::sync::atomic::Ordering::SeqCst) => Err(panic
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "a panic".into())),
        Err(panic) => std::panic::resume_unwind(panic),
    }
}

/// Where the window system's libraries live (their panics' source files).
const WINDOW_SYSTEM: [&str; 4] = ["/winit-", "/x11rb-", "/x11-dl-", "/wayland-"];

/// A window-system error, said without the library's source location.
fn window_error(e: impl std::fmt::Display) -> ViewError {
    ViewError::Window(without_location(&e.to_string()).to_string())
}

/// What winit's "os error at FILE:LINE: what" says.
fn without_location(text: &str) -> &str {
    match text.strip_prefix("os error at ") {
        Some(rest) => rest.split_once(": ").map_or(rest, |(_, what)| what),
        None => text,
    }
}

/// The event loop's handler.
struct App {
    source: Arc<dyn TileSource>,
    options: ViewOptions,
    /// Made when the event loop first resumes.
    state: Option<Viewer>,
    records: Vec<FrameRecord>,
    error: Option<ViewError>,
    /// Ctrl-C or SIGTERM closes the window as Escape does.
    interrupt: crate::interrupt::Interrupt,
}

/// The window and what draws into it.
struct Viewer {
    window: Arc<Window>,
    renderer: Renderer,
    presenter: Presenter,
    flight: fly::Flight,
    /// The tiles of the last frame drawn.
    drawn: Vec<Arc<TileData>>,
    controls: Controls,
    input: Input,
    /// Unit direction to the sun (ECEF), if it is on.
    sun_ecef: Option<DVec3>,
    sun_on: bool,
    traversal: Traversal,
    /// Save the next frame.
    snapshot: bool,
    started: Instant,
    last: Instant,
    /// Frames drawn.
    frames: usize,
    /// Frames drawn when the title was last updated, and when.
    title: (usize, Instant),
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_none() {
            match Viewer::open(event_loop, &self.source, &self.options) {
                Ok(viewer) => {
                    viewer.window.request_redraw();
                    self.state = Some(viewer);
                }
                Err(e) => self.fail(event_loop, e),
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let Some(viewer) = &mut self.state else { return };
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(_) => viewer.presenter.fit(viewer.renderer.gpu()),
            WindowEvent::KeyboardInput { event, is_synthetic, .. } => {
                let PhysicalKey::Code(key) = event.physical_key else { return };
                let pressed = event.state == ElementState::Pressed;
                if pressed && !event.repeat && !is_synthetic && viewer.toggle(key) {
                    event_loop.exit();
                }
                viewer.input.key(key, pressed);
                viewer.controls.held = viewer.input.held();
            }
            WindowEvent::Focused(false) => {
                viewer.input.release_all();
                viewer.controls.held = viewer.input.held();
            }
            WindowEvent::MouseInput { state, button: MouseButton::Left, .. } => {
                viewer.input.button(state == ElementState::Pressed);
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let Some((dx, dy)) = viewer.input.moved(position.x, position.y) {
                    viewer.controls.drag(dx, dy);
                }
            }
            WindowEvent::MouseWheel { delta, .. } => viewer.controls.wheel(match delta {
                MouseScrollDelta::LineDelta(_, lines) => f64::from(lines),
                MouseScrollDelta::PixelDelta(px) => px.y / 40.0,
            }),
            WindowEvent::RedrawRequested => {
                // A scripted run's last frame is kept.
                let last = self.options.exit_after.is_some_and(|n| self.records.len() + 1 >= n);
                viewer.snapshot |= last && self.options.out_dir.is_some();
                match viewer.frame(self.source.as_ref(), &self.options) {
                    Ok(record) => self.records.push(record),
                    Err(e) => return self.fail(event_loop, e),
                }
                if self.options.exit_after.is_some_and(|n| self.records.len() >= n) {
                    event_loop.exit();
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if self.interrupt.came().is_some() {
            return event_loop.exit();
        }
        if let Some(viewer) = &self.state {
            viewer.window.request_redraw();
        }
    }
}

impl App {
    fn fail(&mut self, event_loop: &ActiveEventLoop, error: ViewError) {
        self.error.get_or_insert(error);
        event_loop.exit();
    }
}

impl Viewer {
    fn open(
        event_loop: &ActiveEventLoop,
        source: &Arc<dyn TileSource>,
        options: &ViewOptions,
    ) -> Result<Viewer, ViewError> {
        let (w, h) = options.render.size;
        let attributes =
            Window::default_attributes().with_title("Sylva").with_inner_size(winit::dpi::PhysicalSize::new(w, h));
        let window = Arc::new(event_loop.create_window(attributes).map_err(window_error)?);
        let display = Box::new(event_loop.owned_display_handle());
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(display));
        let surface = instance.create_surface(window.clone()).map_err(window_error)?;
        let gpu = Gpu::open_on(&instance, Some(&surface))?;
        let presenter = Presenter::new(&gpu, instance.clone(), window.clone(), surface)?;
        let r = &options.render;
        let renderer =
            Renderer::new(gpu, source.grid().samples(), r.halo as u32, options.gpu_budget_bytes, r.geomorph)?
                .with_hull_factor(r.hull_factor)
                .with_ray_pass(r.ray_pass);
        // The flight holds the coarse tiles that place a default start. Each
        // frame tells it the camera's motion before it selects.
        let shadows = options.sun.is_some();
        let still = MotionLimits { max_speed_mps: 0.0, max_turn_radps: 0.0 };
        let mut flight =
            fly::Flight::new(source.as_ref(), &renderer, r, Motion { frame_s: 1.0 / 60.0, limits: still, shadows })?;
        let start = options.start.unwrap_or_else(|| default_start(&source.bounds(), flight.envelope()));
        let controls = Controls::new(start, start.eye.height_m);
        flight.load_in_background(source.clone())?;
        let now = Instant::now();
        Ok(Viewer {
            window,
            renderer,
            presenter,
            flight,
            drawn: Vec::new(),
            controls,
            input: Input::default(),
            sun_ecef: options.sun.map(|sun| sun.ecef(start.eye.lon_deg, start.eye.lat_deg)),
            sun_on: shadows,
            traversal: r.traversal,
            snapshot: false,
            started: now,
            last: now,
            frames: 0,
            title: (0, now),
        })
    }

    /// Acts on a key just pressed; true to quit.
    fn toggle(&mut self, key: KeyCode) -> bool {
        match key {
            KeyCode::Escape => return true,
            KeyCode::KeyL => self.sun_on = !self.sun_on && self.sun_ecef.is_some(),
            KeyCode::KeyT => {
                self.traversal = match self.traversal {
                    Traversal::Exact => Traversal::Linear(LINEAR_STEPS),
                    Traversal::Linear(_) => Traversal::Exact,
                }
            }
            KeyCode::KeyP => self.snapshot = true,
            _ => {}
        }
        false
    }

    /// Moves the eye, renders and shows a frame.
    fn frame(&mut self, source: &dyn TileSource, options: &ViewOptions) -> Result<FrameRecord, ViewError> {
        let now = Instant::now();
        // A stall (pipelines built, the window hidden) counts as a long
        // frame, no longer: the controls and the look-ahead agree.
        let dt_s = (now - self.last).as_secs_f64().min(controls::LONGEST_STEP_S);
        self.last = now;
        self.move_eye(source, dt_s);
        let motion = Motion { frame_s: dt_s, limits: self.controls.limits(), shadows: self.sun_on };
        self.flight.set_motion(&options.render, motion);
        let shot = Shot {
            index: self.frames,
            t_s: (now - self.started).as_secs_f64(),
            camera: self.controls.pose.camera(options.fov_deg, self.presenter.size()),
            sun_ecef: self.sun_ecef.filter(|_| self.sun_on),
        };
        let render = FlyOptions { traversal: self.traversal, ..options.render.clone() };
        let readback = if self.snapshot { Readback::Colour } else { Readback::None };
        let framed = self.flight.frame(source, &mut self.renderer, &render, &shot, readback)?;
        if let Some(colour) = self.renderer.colour() {
            self.presenter.show(self.renderer.gpu(), colour)?;
        }
        if std::mem::take(&mut self.snapshot) {
            let dir = options.out_dir.as_deref().unwrap_or(std::path::Path::new("."));
            let size = (shot.camera.width_px, shot.camera.height_px);
            if let Err(e) = fly::write_png(&free_name(dir, shot.index), &framed.rendered, size) {
                // Said, and the view goes on.
                crate::outputs::say(format_args!("sylva view: the frame was not saved: {e}"));
            }
        }
        self.frames += 1;
        self.show_title(&framed.record);
        self.drawn = framed.tiles;
        Ok(framed.record)
    }

    /// Moves the eye by the keys and drag of `dt_s` seconds, then keeps it
    /// above the surface under it: that of the finest tile loaded there and
    /// that of the tile the last frame drew there (a coarser stand-in while
    /// finer tiles load, or a coarser level chosen), whichever is higher.
    fn move_eye(&mut self, source: &dyn TileSource, dt_s: f64) {
        self.controls.step(dt_s);
        let eye = self.controls.pose.eye;
        let finest = self.flight.tile_at(&source.grid(), eye.lon_deg, eye.lat_deg);
        let drawn = self.drawn.iter().filter(|t| t.frame.sector.contains(eye.lon_deg, eye.lat_deg)).cloned();
        let under: Vec<_> = finest.into_iter().chain(drawn).collect();
        self.controls.ground(super::tile::clearance_m(eye, &under));
    }

    /// Frame rate, tiles, height and speed in the title, twice a second.
    fn show_title(&mut self, record: &FrameRecord) {
        let (frames, since) = self.title;
        let elapsed = since.elapsed().as_secs_f64();
        if elapsed < TITLE_EVERY_S {
            return;
        }
        let fps = (self.frames - frames) as f64 / elapsed;
        let gpu = record.gpu_ms.map_or(String::new(), |ms| format!(", GPU {ms:.1} ms"));
        let traversal = match self.traversal {
            Traversal::Exact => "exact".to_string(),
            Traversal::Linear(n) => format!("linear {n}"),
        };
        let loading = match (self.flight.pending(), self.flight.failures()) {
            (0, 0) => String::new(),
            (n, 0) => format!(" ({n} loading)"),
            (n, failed) => format!(" ({n} loading, {failed} failed loads)"),
        };
        self.window.set_title(&format!(
            "Sylva — {fps:.0} frames/s{gpu}, {} tiles{loading}, {traversal}, {:.0} m above the surface, {:.0} m/s{}",
            record.tiles_ray + record.tiles_plain,
            self.controls.clearance_m(),
            self.controls.speed_mps(),
            if self.sun_on { "" } else { ", no sun" },
        ));
        self.title = (self.frames, Instant::now());
    }
}

/// Steps of the linear march that `T` switches to (the dissertation's
/// fastest setting).
const LINEAR_STEPS: u32 = 30;
/// Seconds between title updates.
const TITLE_EVERY_S: f64 = 0.5;

/// `view_NNNNN.png` in `dir` for frame `index`, with a suffix if a file
/// of that name is there (from an earlier view): frames saved never replace
/// others.
fn free_name(dir: &std::path::Path, index: usize) -> PathBuf {
    let name = |k: usize| match k {
        0 => dir.join(format!("view_{index:05}.png")),
        k => dir.join(format!("view_{index:05}-{k}.png")),
    };
    (0..).map(name).find(|p| !p.exists()).unwrap_or_else(|| name(0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_errors_are_said_without_the_librarys_source_location() {
        let os = "os error at /root/.cargo/registry/src/winit-0.30.13/src/platform_impl/linux/mod.rs:765: XOpenDisplay failed";
        assert_eq!(without_location(os), "XOpenDisplay failed");
        assert_eq!(without_location("no display"), "no display");
    }
}
