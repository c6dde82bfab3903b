//! `sylva view` in a window on a virtual X display (Xvfb, which
//! `scripts/setup.sh` installs): scripted runs that close after a few
//! frames, their statistics and last frame, and the error without a
//! display.

use crate::common::{self, TempDir};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};

/// An Xvfb server on a display of its own, stopped on drop.
struct VirtualDisplay {
    child: Child,
    name: String,
}

impl VirtualDisplay {
    fn start() -> VirtualDisplay {
        // Xvfb picks a free display and writes its number to stdout.
        let mut child = Command::new("Xvfb")
            .args(["-displayfd", "1", "-screen", "0", "320x240x24", "-nolisten", "tcp"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb (apt-get install -y xvfb; scripts/setup.sh installs it)");
        let mut line = String::new();
        let stdout = child.stdout.take().expect("Xvfb's stdout");
        std::io::BufRead::read_line(&mut std::io::BufReader::new(stdout), &mut line).expect("Xvfb's display");
        assert!(line.trim().parse::<u32>().is_ok(), "Xvfb did not start: {line:?}");
        VirtualDisplay { child, name: format!(":{}", line.trim()) }
    }
}

impl Drop for VirtualDisplay {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn view(display: Option<&str>, args: &[&str]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_sylva"));
    command.arg("view").args(args).env("XDG_RUNTIME_DIR", std::env::temp_dir()).env_remove("WAYLAND_DISPLAY");
    match display {
        Some(name) => command.env("DISPLAY", name),
        None => command.env_remove("DISPLAY"),
    };
    command.output().expect("run sylva view")
}

/// An open-ended `sylva view` on `display` writing into `out`.
fn spawn_view(display: &VirtualDisplay, out: &Path) -> Child {
    let mut command = Command::new(env!("CARGO_BIN_EXE_sylva"));
    command.args(["view", "--size", "64x48", "--out", out.to_str().unwrap()]);
    command.env("XDG_RUNTIME_DIR", std::env::temp_dir()).env_remove("WAYLAND_DISPLAY").env("DISPLAY", &display.name);
    command.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("run sylva view")
}

/// The rows of a `stats.csv`, without its header.
fn rows(out: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(out.join("stats.csv")).expect("stats.csv");
    text.lines().skip(1).map(str::to_string).collect()
}

#[test]
fn a_scripted_view_closes_after_its_frames_with_statistics_and_the_last_frame() {
    let display = VirtualDisplay::start();
    let dir = TempDir::new("view-demo");
    let out = dir.join("out");
    let output = view(Some(&display.name), &["--frames", "4", "--size", "96x64", "--out", out.to_str().unwrap()]);
    assert!(output.status.success(), "sylva view failed: {}", String::from_utf8_lossy(&output.stderr));
    assert!(String::from_utf8_lossy(&output.stdout).starts_with("4 frames"));
    assert_eq!(rows(&out).len(), 4);
    // The default start looks down over the demo valley: mostly ground.
    let share = common::ground_share(&out.join("view_00003.png"), 0.0..1.0);
    assert!(share > 0.5, "{share}");
}

#[test]
fn ctrl_c_closes_a_view_with_its_statistics() {
    // Regression: the event loop did not watch the signal, so Ctrl-C ended
    // the process and no stats.csv was written.
    let display = VirtualDisplay::start();
    let dir = TempDir::new("view-signal");
    let out = dir.join("out");
    let view = spawn_view(&display, &out);
    std::thread::sleep(std::time::Duration::from_secs(8));
    let sent = Command::new("kill").arg("-INT").arg(view.id().to_string()).status();
    assert!(sent.unwrap().success());
    let output = view.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "128 + the signal: {stderr}");
    assert!(stderr.contains(&format!("closed by signal 2; its stats.csv is in {}", out.display())), "{stderr}");
    let frames = rows(&out).len();
    assert!(String::from_utf8_lossy(&output.stdout).starts_with(&format!("{frames} frames")));
}

#[test]
fn a_display_that_goes_away_ends_the_view_with_an_error_and_its_statistics() {
    // Regression: winit panicked on the lost X connection (exit 101, no
    // stats.csv).
    let display = VirtualDisplay::start();
    let dir = TempDir::new("view-lost");
    let out = dir.join("out");
    let view = spawn_view(&display, &out);
    std::thread::sleep(std::time::Duration::from_secs(8));
    drop(display);
    let output = view.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    // Whichever library notices first: winit (its panic, caught: the
    // statistics written) or Xlib, whose handler ends the process itself
    // ("X connection to :0 broken", or "XIO: fatal IO error" mid-request).
    if stderr.contains("the window system failed") {
        assert!(stderr.contains(&format!("its stats.csv is in {}", out.display())), "{stderr}");
        assert!(!rows(&out).is_empty(), "the frames drawn in 8 s have their statistics");
    } else {
        let xlib = (stderr.contains("X connection to") && stderr.contains("broken")) || stderr.contains("XIO:");
        assert!(xlib, "{stderr}");
    }
}

#[test]
fn a_view_starts_on_a_path_and_flies_under_a_budget() {
    let display = VirtualDisplay::start();
    let dir = TempDir::new("view-budget");
    let out = dir.join("out");
    let path = common::repo().join("config/paths/demo_valley.toml");
    let args = [
        "--path",
        path.to_str().unwrap(),
        "--lod",
        "budget",
        "--budget-ms",
        "200",
        "--frames",
        "3",
        "--size",
        "96x64",
        "--out",
        out.to_str().unwrap(),
    ];
    let output = view(Some(&display.name), &args);
    assert!(output.status.success(), "sylva view failed: {}", String::from_utf8_lossy(&output.stderr));
    let rows = rows(&out);
    assert_eq!(rows.len(), 3);
    // Under a budget every frame is priced before it is drawn.
    let header = std::fs::read_to_string(out.join("stats.csv")).unwrap();
    let column = header.lines().next().unwrap().split(',').position(|h| h == "predicted_ms").unwrap();
    for row in &rows {
        let predicted: f64 = row.split(',').nth(column).unwrap().parse().unwrap();
        assert!(predicted > 0.0, "{row}");
    }
    assert!(common::ground_share(&out.join("view_00002.png"), 0.0..1.0) > 0.2);
}

#[test]
fn without_a_display_the_view_says_so() {
    let dir = TempDir::new("view-no-display");
    let out = dir.join("new");
    let output = view(None, &["--frames", "1", "--out", out.to_str().unwrap()]);
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("needs a display"), "{stderr}");
    assert!(!out.exists(), "the --out it made and left empty is gone");
}
