//! `sylva fly` against a server that has no tile: what it says.

use crate::common::{self, TempDir};
use crate::fly::fly;
use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A loopback server that answers `/tiles.json` as `sylva serve` does on
/// the demo region, and every other request with 404, as it does for a
/// tile without data: its address, and the count of those other requests.
fn tileless_server() -> (String, Arc<AtomicUsize>) {
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
                let reply = match head.starts_with("GET /tiles.json ") {
                    true => ok(
                        r#"{"name":"demo","level0_delta_deg":36.0,"samples":513,"bounds":[10.0,46.3,10.25,46.45],"max_halo":64}"#,
                    ),
                    false => {
                        count.fetch_add(1, Ordering::SeqCst);
                        "HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_string()
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

#[test]
fn a_flight_whose_server_has_no_tile_says_so() {
    // Regression, from a user's trial: a server that answered every tile
    // request with 404 (a wrong URL path behind a proxy) ended the flight
    // with "the GPU tile cache held no cut at the asked 2 px error" and "no
    // frame drew a tile: does the camera look at the region?".
    let dir = TempDir::new("fly-no-tile");
    let (base, asked) = tileless_server();
    let path = common::repo().join("config/paths/demo_valley.toml");
    let args = ["--server", &base, "--path", path.to_str().unwrap(), "--frames", "2", "--size", "32x24"];
    let summary = fly(&args, &dir.join("out"));
    let n = asked.load(Ordering::SeqCst);
    assert!(n > 0, "tiles were asked for");
    let said = format!("no frame drew a tile: the server at {base} had no tile for any request: {n} requests, all 404");
    assert!(summary.contains(&said), "{summary}");
    assert!(!summary.contains("GPU tile cache") && !summary.contains("does the camera look"), "{summary}");
}
