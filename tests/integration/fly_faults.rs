//! `sylva fly` against a server that has no tile or never answers, and
//! stopped at once by a second signal: what it says, and what it leaves in
//! its output directory.

use crate::common::{self, TempDir};
use crate::fly::{fly, spawn_fly, stats, wait_for};
use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// How the loopback server of [`tileless_server`] answers a tile request.
#[derive(Clone, Copy)]
enum Tiles {
    /// 404, as a server does for a tile without data.
    NotFound,
    /// Never.
    Hang,
}

/// A loopback server that answers `/tiles.json` as `sylva serve` does on
/// the demo region, and every other request by `tiles`: its address, and
/// the count of those other requests.
fn tileless_server(tiles: Tiles) -> (String, Arc<AtomicUsize>) {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    let asked = Arc::new(AtomicUsize::new(0));
    let count = asked.clone();
    std::thread::spawn(move || {
        for mut stream in listener.incoming().flatten() {
            let count = count.clone();
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                let n = stream.read(&mut buf).unwrap_or(0);
                let head = String::from_utf8_lossy(&buf[..n]);
                let reply = match (head.starts_with("GET /tiles.json "), tiles) {
                    (true, _) => ok(
                        r#"{"name":"demo","level0_delta_deg":36.0,"samples":513,"bounds":[10.0,46.3,10.25,46.45],"max_halo":64}"#,
                    ),
                    (false, Tiles::NotFound) => {
                        count.fetch_add(1, Ordering::SeqCst);
                        "HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_string()
                    }
                    (false, Tiles::Hang) => {
                        count.fetch_add(1, Ordering::SeqCst);
                        std::thread::sleep(Duration::from_secs(600));
                        return;
                    }
                };
                let _ = stream.write_all(reply.as_bytes());
            });
        }
    });
    (base, asked)
}

/// A 200 response with a JSON `body`.
fn ok(body: &str) -> String {
    format!(
        "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
}

/// Sends SIGINT to `child`.
fn interrupt(child: &std::process::Child) {
    let sent = std::process::Command::new("kill").arg("-INT").arg(child.id().to_string()).status();
    assert!(sent.unwrap().success());
}

#[test]
fn a_flight_whose_server_has_no_tile_says_so() {
    // Regression, from a user's trial: a server that answered every tile
    // request with 404 (a wrong URL path behind a proxy) ended the flight
    // with "the GPU tile cache held no cut at the asked 2 px error" and "no
    // frame drew a tile: does the camera look at the region?".
    let dir = TempDir::new("fly-no-tile");
    let (base, asked) = tileless_server(Tiles::NotFound);
    let path = common::repo().join("config/paths/demo_valley.toml");
    let args = ["--server", &base, "--path", path.to_str().unwrap(), "--frames", "2", "--size", "32x24"];
    let summary = fly(&args, &dir.join("out"));
    let n = asked.load(Ordering::SeqCst);
    assert!(n > 0, "tiles were asked for");
    let said = format!("no frame drew a tile: the server at {base} had no tile for any request: {n} requests, all 404");
    assert!(summary.contains(&said), "{summary}");
    assert!(!summary.contains("GPU tile cache") && !summary.contains("does the camera look"), "{summary}");
}

#[test]
fn a_second_signal_before_the_first_frame_leaves_no_directory() {
    // Regression, from a user's trial: the second Ctrl-C, which ends a
    // flight at once, left the empty --out it had made.
    let dir = TempDir::new("fly-twice-start");
    let (base, asked) = tileless_server(Tiles::Hang);
    let (made, out) = (dir.join("made"), dir.join("made/out"));
    let path = common::repo().join("config/paths/demo_valley.toml");
    let args = ["--server", &base, "--path", path.to_str().unwrap(), "--frames", "5", "--size", "32x24"];
    let flight = spawn_fly(&args, &out);
    // Its first frame waits on its tiles.
    let deadline = Instant::now() + Duration::from_secs(60);
    while asked.load(Ordering::SeqCst) == 0 {
        assert!(Instant::now() < deadline, "no tile was asked for");
        std::thread::sleep(Duration::from_millis(20));
    }
    interrupt(&flight);
    std::thread::sleep(Duration::from_millis(300));
    interrupt(&flight);
    let output = flight.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(!made.exists(), "an empty directory is left: {stderr}");
}

#[test]
fn a_second_signal_keeps_the_statistics_of_the_frames_finished() {
    // Regression, from a user's trial: the second Ctrl-C left the frames
    // finished and no stats.csv.
    let dir = TempDir::new("fly-twice");
    let out = dir.join("out");
    let path = common::repo().join("config/paths/demo_valley.toml");
    // Each frame held 3 s: both signals come during the second one.
    let args = ["--path", path.to_str().unwrap(), "--frames", "500", "--size", "32x24", "--hold-ms", "3000"];
    let flight = spawn_fly(&args, &out);
    wait_for(&out.join("frame_00000.png"));
    interrupt(&flight);
    std::thread::sleep(Duration::from_millis(300));
    interrupt(&flight);
    let output = flight.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(!stderr.contains("stopped after"), "ended at once, not after the frame in hand: {stderr}");
    let names: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(names.contains(&"frame_00000.png".to_string()) && !names.contains(&"frame_00001.png".to_string()));
    let rows = stats(&out);
    assert_eq!(rows.iter().map(|r| r["frame"].as_str()).collect::<Vec<_>>(), ["0"], "{names:?}");
}
