//! Many seeders and servers on one cache: two processes seeding the same
//! shard, and four shards in parallel, on the directory cache and on a real
//! Redis server (Debian's `redis-server`, started here on a Unix socket),
//! finish with a complete cache identical to one process's run, each tile
//! made once; servers on Redis answer the seeded tiles as cache hits.

use crate::common::TempDir;
use crate::http::Server;
use crate::seed::{count, ok, product_of, rmnp_config, seed_command, tiles};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};
use sylva::cache::{Lookup, TileStore};

/// A `redis-server` on a Unix socket in a temporary directory.
pub struct Redis {
    child: Child,
    /// `redis+unix://…`.
    pub url: String,
    _dir: TempDir,
}

impl Redis {
    /// Starts one; `tag` names its directory.
    pub fn start(tag: &str) -> Redis {
        let dir = TempDir::new(tag);
        let socket = dir.join("redis.sock");
        let child = Command::new("redis-server")
            .args([
                "--port",
                "0",
                "--unixsocket",
                socket.to_str().unwrap(),
                "--unixsocketperm",
                "700",
                "--save",
                "",
                "--appendonly",
                "no",
            ])
            .stdout(Stdio::null())
            .spawn()
            .expect("redis-server (apt-get install redis-server; scripts/setup.sh installs it)");
        let url = format!("redis+unix://{}", socket.display());
        let start = Instant::now();
        while sylva::cache::redis::RedisStore::open(&url, "").is_err() {
            assert!(start.elapsed() < Duration::from_secs(20), "redis-server did not start");
            std::thread::sleep(Duration::from_millis(20));
        }
        Redis { child, url, _dir: dir }
    }

    fn store(&self) -> sylva::cache::redis::RedisStore {
        sylva::cache::redis::RedisStore::open(&self.url, "sylva:").unwrap()
    }
}

impl Drop for Redis {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The job every test seeds: rmnp's DEM, levels 6-10 (224 tiles).
fn job(config: &Path) -> Vec<String> {
    ["--config", config.to_str().unwrap(), "--layers", "dem", "--levels", "6-10", "--concurrency", "1"]
        .map(String::from)
        .to_vec()
}

/// Runs seeders at once, each with `job` plus its own arguments, in `dir`.
fn together(dir: &Path, job: &[String], each: &[Vec<String>]) -> Vec<Output> {
    let children: Vec<Child> = each
        .iter()
        .map(|extra| {
            let args: Vec<&str> = job.iter().chain(extra).map(String::as_str).collect();
            seed_command(dir, &args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap()
        })
        .collect();
    children.into_iter().map(|c| c.wait_with_output().unwrap()).collect()
}

fn made(outputs: &[Output]) -> u64 {
    outputs.iter().map(|o| count(&ok(o), "tile files made")).sum()
}

/// The reference: one process, directory cache.
fn reference(dir: &TempDir, config: &Path) -> BTreeMap<String, Vec<u8>> {
    let cache = dir.join("reference");
    let args: Vec<String> = job(config)
        .into_iter()
        .chain(["--cache-dir".into(), cache.display().to_string(), "--progress-file".into(), "ref.json".into()])
        .collect();
    ok(&seed_command(&dir.0, &args.iter().map(String::as_str).collect::<Vec<_>>()).output().unwrap());
    tiles(&cache)
}

fn shard_args(i: u32, extra: &[String]) -> Vec<String> {
    let mut a = vec!["--shard".to_string(), format!("{i}/4")];
    a.extend_from_slice(extra);
    a
}

fn files(prefix: &str) -> Vec<String> {
    vec!["--progress-file".into(), format!("{prefix}.json"), "--failed-file".into(), format!("{prefix}.txt")]
}

/// One of two seeders on the same job: it keeps what the other finished
/// (whenever it started); what the other is making, it waits for.
fn twin(prefix: &str) -> Vec<String> {
    [files(prefix), vec!["--skip-existing".into()]].concat()
}

#[test]
fn seeders_sharing_a_directory_cache_match_one_process() {
    let dir = TempDir::new("seed-dir-shared");
    let config = rmnp_config(&dir, "rmnp.toml", "[tile_cache]\nlock_ttl_s = 5");
    let expected = reference(&dir, &config);
    // Two processes on the same (whole) job and cache.
    let same: PathBuf = dir.join("same");
    let cache = |p: &Path| vec!["--cache-dir".to_string(), p.display().to_string()];
    let twins =
        together(&dir.0, &job(&config), &[[cache(&same), twin("a")].concat(), [cache(&same), twin("b")].concat()]);
    assert_eq!(made(&twins), expected.len() as u64, "each tile made once by the two");
    assert!(tiles(&same) == expected, "two seeders on one job differ from one");
    // Four shards at once.
    let sharded = dir.join("sharded");
    let each: Vec<Vec<String>> = (0..4).map(|i| shard_args(i, &cache(&sharded))).collect();
    let outs = together(&dir.0, &job(&config), &each);
    assert_eq!(made(&outs), expected.len() as u64);
    assert!(tiles(&sharded) == expected, "four shards differ from one process");
}

/// Every reference entry is in Redis, identical; no lock is left.
fn assert_redis_holds(redis: &Redis, expected: &BTreeMap<String, Vec<u8>>) {
    let store = redis.store();
    for (key, bytes) in expected {
        match store.get(key).unwrap() {
            Lookup::Hit(s) => assert!(s.bytes == *bytes, "{key} differs in Redis"),
            other => panic!("{key}: {other:?} in Redis"),
        }
    }
    let mut conn = redis::Client::open(redis.url.as_str()).unwrap().get_connection().unwrap();
    let locks: Vec<String> = redis::cmd("KEYS").arg("sylva:lock:*").query(&mut conn).unwrap();
    assert!(locks.is_empty(), "locks left: {locks:?}");
}

#[test]
fn seeders_and_servers_sharing_redis_match_one_process() {
    let dir = TempDir::new("seed-redis");
    let redis = Redis::start("seed-redis-server");
    let plain = rmnp_config(&dir, "rmnp.toml", "");
    let expected = reference(&dir, &plain);
    let config = rmnp_config(
        &dir,
        "redis.toml",
        &format!("[tile_cache]\nbackend = \"redis\"\nredis_url = \"{}\"\nlock_ttl_s = 5", redis.url),
    );
    // Two processes on the same job.
    let twins = together(&dir.0, &job(&config), &[twin("a"), twin("b")]);
    assert_eq!(made(&twins), expected.len() as u64, "each tile made once by the two");
    assert_redis_holds(&redis, &expected);
    // Two server replicas answer the seeded tiles from Redis, computing none.
    let replicas = [Server::start_on_config_cache(&config), Server::start_on_config_cache(&config)];
    for (i, (key, bytes)) in expected.iter().enumerate() {
        let (_, path) = product_of(key).unwrap();
        let reply = replicas[i % 2].get(&path);
        assert_eq!(reply.status, 200, "{path}");
        assert!(reply.body == *bytes, "{path}");
    }
    for server in &replicas {
        assert_eq!(server.metric("sylva_tile_computations_total"), 0.0);
    }
    // Four shards at once on a fresh Redis database.
    let redis2 = Redis::start("seed-redis-server-2");
    let config2 = rmnp_config(
        &dir,
        "redis2.toml",
        &format!("[tile_cache]\nbackend = \"redis\"\nredis_url = \"{}\"\nlock_ttl_s = 5", redis2.url),
    );
    let each: Vec<Vec<String>> = (0..4).map(|i| shard_args(i, &files(&format!("s{i}")))).collect();
    let outs = together(&dir.0, &job(&config2), &each);
    assert_eq!(made(&outs), expected.len() as u64);
    assert_redis_holds(&redis2, &expected);
}

/// An upstream of Terrarium tiles answering each request after `delay`,
/// counting the requests per path.
fn slow_upstream(delay: Duration) -> (String, std::sync::Arc<std::sync::Mutex<BTreeMap<String, u32>>>) {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    let requests: std::sync::Arc<std::sync::Mutex<BTreeMap<String, u32>>> = Default::default();
    let counted = requests.clone();
    std::thread::spawn(move || {
        for mut stream in listener.incoming().flatten() {
            let counted = counted.clone();
            std::thread::spawn(move || {
                let mut buf = [0u8; 2048];
                let n = stream.read(&mut buf).unwrap_or(0);
                let path = String::from_utf8_lossy(&buf[..n]).split_whitespace().nth(1).unwrap_or("").to_string();
                *counted.lock().unwrap().entry(path.clone()).or_default() += 1;
                std::thread::sleep(delay);
                let png = crate::seed::terrarium_tile(&path).unwrap_or_default();
                let head = format!(
                    "HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                    png.len()
                );
                let _ = stream.write_all(&[head.into_bytes(), png].concat());
            });
        }
    });
    (base, requests)
}

#[test]
fn a_tile_slower_than_the_lock_expiry_is_computed_once_by_two_servers() {
    // Its holder renews the lock while it computes: the other server waits
    // for the tile rather than taking the lock over and computing it again.
    let dir = TempDir::new("lease-servers");
    let (base, requests) = slow_upstream(Duration::from_millis(1500));
    let config = dir.join("slow.toml");
    std::fs::write(
        &config,
        format!(
            "name = \"slow\"\n[dem.upstream]\nservice = \"terrarium\"\nurl = \"{base}/{{z}}/{{x}}/{{y}}.png\"\nzoom = 13\nbounds = [9.9, 46.2, 10.2, 46.5]\nretries = 0\n[tile_cache]\nlock_ttl_s = 1\n"
        ),
    )
    .unwrap();
    let cache = dir.join("cache");
    let servers = [Server::start(Some(&config), &cache), Server::start(Some(&config), &cache)];
    let before: u32 = requests.lock().unwrap().values().sum();
    let t = crate::common::demo().tiles.tile_containing(10.1, 46.35, 10);
    let path = format!("/tiles/dem/{}/{}/{}_{}.bil", t.level, t.row, t.row, t.col);
    let replies: Vec<_> = std::thread::scope(|s| {
        let asks: Vec<_> = servers.iter().map(|server| s.spawn(|| server.get(&path))).collect();
        asks.into_iter().map(|a| a.join().unwrap()).collect()
    });
    assert!(replies.iter().all(|r| r.status == 200) && replies[0].body == replies[1].body);
    let counts = requests.lock().unwrap().clone();
    let asked: u32 = counts.values().sum::<u32>() - before;
    assert!(asked > 0, "the tile was read from the upstream");
    assert!(counts.values().all(|&n| n == 1), "an upstream tile asked for twice: {counts:?}");
    let computed: f64 = servers.iter().map(|s| s.metric("sylva_tile_computations_total")).sum();
    assert_eq!(computed, 1.0);
}
