//! `sylva cache` as an operator runs it: a seeded directory cache with a
//! stale version beside it is listed, the stale version removed (one in use
//! kept), the cache trimmed to a size oldest tiles first, and a server on
//! the trimmed cache answers every tile as before, the trimmed ones
//! computed again; the same on a real Redis.

use crate::common::TempDir;
use crate::http::Server;
use crate::seed::{ok, product_of, rmnp_config, seed, tiles, walk};
use crate::seed_shared::Redis;
use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, SystemTime};
use sylva::cache::prune::{Plan, prune, usage};
use sylva::cache::{Backend, Lookup, TileStore};

const STALE: &str = "v00000000000000ee";

/// `sylva cache ARGS`.
fn cache(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sylva")).arg("cache").args(args).output().expect("run sylva cache")
}

/// Sets `files` (links themselves, not their targets) written and read
/// `minutes` ago.
fn age(files: &[std::path::PathBuf], minutes: u64) {
    let t = SystemTime::now() - Duration::from_secs(minutes * 60);
    let stamp = format!("@{}", t.duration_since(SystemTime::UNIX_EPOCH).unwrap().as_secs());
    for chunk in files.chunks(500) {
        assert!(Command::new("touch").arg("-h").arg("-d").arg(&stamp).args(chunk).status().unwrap().success());
    }
}

/// Blocks a file or link takes, in bytes.
fn taken(path: &Path) -> u64 {
    std::os::unix::fs::MetadataExt::blocks(&std::fs::symlink_metadata(path).unwrap()) * 512
}

/// What `du` says a directory takes.
fn du(path: &Path) -> u64 {
    let out = Command::new("du").arg("-sB1").arg(path).output().unwrap();
    String::from_utf8(out.stdout).unwrap().split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn a_directory_cache_is_listed_pruned_and_trimmed_and_serves_every_tile_after() {
    let dir = TempDir::new("cache-prune");
    let root = dir.join("cache");
    let root_arg = root.to_str().unwrap();
    ok(&seed(&dir.0, &["--cache-dir", root_arg, "--levels", "9-11", "--formats", "bil16,bil32"]));
    let seeded = tiles(&root);
    let current = std::fs::read_dir(&root).unwrap().next().unwrap().unwrap().file_name().into_string().unwrap();
    assert!(root.join(&current).join(".in-use").exists(), "the seeder marks its version in use");
    // A version left by an earlier configuration, unused for three hours.
    let copied = Command::new("cp").arg("-a").arg(root.join(&current)).arg(root.join(STALE)).status().unwrap();
    assert!(copied.success());
    age(&walk(&root.join(STALE)), 180);

    let listed = ok(&cache(&["usage", "--cache-dir", root_arg]));
    let line =
        |v: &str| listed.lines().find(|l| l.starts_with(v)).unwrap_or_else(|| panic!("{v}: {listed}")).to_string();
    assert!(line(&current).ends_with("current (Sylva demo (Val Selva))"), "{listed}");
    assert!(line(STALE).ends_with("stale") && line(STALE).contains(&format!(" {} ", seeded.len())), "{listed}");

    // Nothing asked: a usage error.
    assert_eq!(cache(&["prune", "--cache-dir", root_arg]).status.code(), Some(2));
    let dry = ok(&cache(&["prune", "--cache-dir", root_arg, "--stale", "--dry-run"]));
    assert!(dry.contains(&format!("would remove stale version {STALE} ({} tiles", seeded.len())), "{dry}");
    assert!(root.join(STALE).exists());
    let pruned = ok(&cache(&["prune", "--cache-dir", root_arg, "--stale"]));
    assert!(pruned.contains(&format!("removed stale version {STALE} ({} tiles", seeded.len())), "{pruned}");
    assert!(!root.join(STALE).exists() && root.join(&current).exists());

    // Half the tiles a day old, the other half fresh: a trim to a bit more
    // than the fresh half removes the old half alone.
    let old: Vec<&String> = seeded.keys().filter(|k| k.contains(".bil32")).collect();
    age(&old.iter().map(|k| root.join(k)).collect::<Vec<_>>(), 24 * 60);
    let old_bytes: u64 = old.iter().map(|k| taken(&root.join(k))).sum();
    let max = du(&root.join(&current)) - old_bytes + 1;
    let trimmed = ok(&cache(&["prune", "--cache-dir", root_arg, "--max-size", &max.to_string()]));
    assert!(trimmed.contains(&format!("trimmed {} least recently used tiles and shared", old.len())), "{trimmed}");
    let left = tiles(&root);
    assert_eq!(left.len(), seeded.len() - old.len());
    assert!(left.keys().all(|k| !k.contains(".bil32")));
    assert!(du(&root.join(&current)) <= max);

    // The server answers every tile as seeded: the trimmed ones computed again.
    let server = Server::start(None, &root);
    for (key, bytes) in &seeded {
        let (_, path) = product_of(key).unwrap();
        let reply = server.get(&path);
        assert!(reply.status == 200 && reply.body == *bytes, "{path}");
    }
    assert_eq!(server.metric("sylva_tile_computations_total"), old.len() as f64);

    // Pruned for another region, the demo's version is stale: refused, as
    // that region has no tiles here. Forced, with everything of the demo's
    // aged three hours (its mark too), it is kept while a server runs on it
    // (which marks it), and removed once none does.
    let rmnp = rmnp_config(&dir, "rmnp.toml", "");
    let other = ["prune", "--config", rmnp.to_str().unwrap(), "--cache-dir", root_arg, "--stale"];
    let refused = cache(&other);
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(refused.status.code() == Some(1) && said.contains("none of the current versions"), "{said}");
    drop(server);
    let forced = [&other[..], &["--force"]].concat();
    let mark = root.join(&current).join(".in-use");
    age(&walk(&root.join(&current)), 180);
    let server = Server::start(None, &root);
    let start = std::time::Instant::now();
    while std::fs::metadata(&mark).unwrap().modified().unwrap().elapsed().unwrap() > Duration::from_secs(60) {
        assert!(start.elapsed() < Duration::from_secs(20), "the server did not mark its version");
        std::thread::sleep(Duration::from_millis(50));
    }
    let kept = ok(&cache(&forced));
    assert!(kept.contains(&format!("kept stale version {current}")) && kept.contains("in use"), "{kept}");
    drop(server);
    age(&walk(&root.join(&current)), 180);
    let removed = ok(&cache(&forced));
    assert!(removed.contains(&format!("removed stale version {current}")), "{removed}");
    assert!(!root.join(&current).exists());
}

#[test]
fn a_redis_cache_loses_its_stale_versions_and_is_trimmed_oldest_written_first() {
    let dir = TempDir::new("cache-prune-redis");
    let redis = Redis::start("cache-prune-redis-server");
    let config =
        rmnp_config(&dir, "redis.toml", &format!("[tile_cache]\nbackend = \"redis\"\nredis_url = \"{}\"", redis.url));
    ok(&seed(&dir.0, &["--config", config.to_str().unwrap(), "--layers", "dem", "--levels", "6-9"]));
    let backend = Backend::Redis { url: redis.url.clone(), prefix: "sylva:".into() };
    let (_, versions) = usage(&backend).unwrap();
    let [current] = &versions[..] else { panic!("{versions:?}") };
    // A stale version written three hours ago, one written just now, and
    // keys that are not Sylva's tiles.
    let mut conn = ::redis::Client::open(redis.url.as_str()).unwrap().get_connection().unwrap();
    let stamped = |minutes: u64| {
        let ms =
            (SystemTime::now() - Duration::from_secs(minutes * 60)).duration_since(SystemTime::UNIX_EPOCH).unwrap();
        [b"TILE".as_slice(), &(ms.as_millis() as u64).to_le_bytes(), &[0; 100]].concat()
    };
    let set = |conn: &mut ::redis::Connection, key: &str, value: &[u8]| {
        ::redis::cmd("SET").arg(key).arg(value).query::<()>(conn).unwrap();
    };
    for col in 0..3 {
        set(&mut conn, &format!("sylva:{STALE}/dem/6/1/1_{col}.bil"), &stamped(180));
    }
    // Its server stopped three hours ago: its last mark is as old.
    set(&mut conn, &format!("sylva:in-use:{STALE}"), &stamped(180));
    let recent = "sylva:v00000000000000ff/dem/6/1/1_0.bil";
    set(&mut conn, recent, &stamped(5));
    set(&mut conn, "sylva:notes/readme", b"x");
    set(&mut conn, "other:v00000000000000dd/dem/6/1/1_0.bil", &stamped(180));

    // Another version marked in use by its server, its tiles old; a lock
    // held in the current version.
    let marked = "v00000000000000cc";
    set(&mut conn, &format!("sylva:{marked}/dem/6/1/1_0.bil"), &stamped(180));
    let store = sylva::cache::redis::RedisStore::open(&redis.url, "sylva:").unwrap();
    store.mark_in_use(marked).unwrap();
    let lock = format!("sylva:lock:{}/dem/6/1/1_0.bil", current.version);
    set(&mut conn, &lock, b"holder");

    let plan = |stale, max_bytes| Plan {
        keep: vec![current.version.clone()],
        stale,
        force: false,
        max_bytes,
        grace: Duration::from_secs(3600),
        dry_run: false,
    };
    let pruned = prune(&backend, &plan(true, None), SystemTime::now()).unwrap();
    let names = |v: &[sylva::cache::prune::VersionUsage]| v.iter().map(|v| v.version.clone()).collect::<Vec<_>>();
    assert_eq!(names(&pruned.removed), [STALE]);
    assert_eq!(pruned.removed[0].tiles, 3);
    assert_eq!(names(&pruned.in_use), ["v00000000000000cc", "v00000000000000ff"]);
    let keys: Vec<String> = ::redis::cmd("KEYS").arg("*").query(&mut conn).unwrap();
    assert!(!keys.iter().any(|k| k.contains(STALE)), "{keys:?}");
    for kept in ["sylva:notes/readme", "other:v00000000000000dd/dem/6/1/1_0.bil", recent] {
        assert!(keys.iter().any(|k| k == kept), "{kept}");
    }

    // Trimmed to half its size, the cache loses its oldest written entries
    // first (the marked version's, then the recent one's, both older than
    // the seed), then the seed's; locks and marks stay; nothing left reads
    // damaged.
    let ours = |conn: &mut ::redis::Connection| ::redis::cmd("KEYS").arg("sylva:*").query::<Vec<String>>(conn).unwrap();
    let before = ours(&mut conn).len() as u64;
    let half = pruned.bytes_after / 2;
    let trimmed = prune(&backend, &plan(false, Some(half)), SystemTime::now()).unwrap();
    assert!(trimmed.trimmed.0 > 2 && trimmed.bytes_after <= half, "{trimmed:?}");
    let exists =
        |conn: &mut ::redis::Connection, key: &str| ::redis::cmd("EXISTS").arg(key).query::<bool>(conn).unwrap();
    assert!(!exists(&mut conn, recent) && !exists(&mut conn, &format!("sylva:{marked}/dem/6/1/1_0.bil")));
    assert!(exists(&mut conn, &lock) && exists(&mut conn, &format!("sylva:in-use:{marked}")));
    let left = ours(&mut conn);
    assert_eq!(left.len() as u64, before - trimmed.trimmed.0);
    let (_, after) = usage(&backend).unwrap();
    assert_eq!(after.iter().map(|v| v.bytes).sum::<u64>(), trimmed.bytes_after);
    for key in left.iter().filter(|k| k.starts_with(&format!("sylva:{}/", current.version))) {
        assert!(!matches!(store.get(key.strip_prefix("sylva:").unwrap()).unwrap(), Lookup::Corrupt), "{key}");
    }
}

#[test]
fn a_server_holds_its_cache_to_max_size_and_serves_every_tile_after() {
    let dir = TempDir::new("cache-quota");
    let root = dir.join("cache");
    ok(&seed(&dir.0, &["--cache-dir", root.to_str().unwrap(), "--levels", "9-11", "--formats", "bil16"]));
    let seeded = tiles(&root);
    let version = std::fs::read_dir(&root).unwrap().next().unwrap().unwrap().path();
    let max = du(&version) / 2;
    let config = dir.join("bounded.toml");
    std::fs::write(&config, format!("[tile_cache]\nmax_size = \"{max} B\"\ntrim_interval_s = 86400\n")).unwrap();

    // The server trims as it starts, the least recently used tiles first.
    let server = Server::start(Some(&config), &root);
    let start = std::time::Instant::now();
    while server.metric("sylva_tile_cache_trimmed_tiles_total") == 0.0 {
        assert!(start.elapsed() < Duration::from_secs(30), "the server did not trim its cache");
        std::thread::sleep(Duration::from_millis(100));
    }
    let trimmed = server.metric("sylva_tile_cache_trimmed_tiles_total");
    assert!(du(&version) <= max, "{} > {max}", du(&version));
    assert_eq!(tiles(&root).len() as f64, seeded.len() as f64 - trimmed);
    assert!(server.metric("sylva_tile_cache_bytes") <= max as f64);
    for (key, bytes) in &seeded {
        let (_, path) = product_of(key).unwrap();
        let reply = server.get(&path);
        assert!(reply.status == 200 && reply.body == *bytes, "{path}");
    }
    assert_eq!(server.metric("sylva_tile_computations_total"), trimmed);
    drop(server);

    // A seed writing more than the bound says so: the servers will trim it.
    let root_arg = root.to_str().unwrap();
    let more =
        ["--config", config.to_str().unwrap(), "--cache-dir", root_arg, "--levels", "9-12", "--formats", "bil16"];
    let said = ok(&seed(&dir.0, &more));
    assert!(said.contains("more than [tile_cache] max_size"), "{said}");

    // A bound that is no size is refused, naming the file and the key.
    std::fs::write(&config, "[tile_cache]\nmax_size = \"lots\"\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sylva")).args(["info", "--config"]).arg(&config).output().unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && said.contains("bounded.toml") && said.contains("max_size"), "{said}");
}

#[test]
fn servers_on_redis_trim_one_at_a_time_and_the_holder_alone_renews() {
    let redis = Redis::start("cache-quota-redis");
    let backend = Backend::Redis { url: redis.url.clone(), prefix: "sylva:".into() };
    let open = || sylva::cache::redis::RedisStore::open(&redis.url, "sylva:").unwrap();
    let (one, other) = (open(), open());
    let limit = sylva::cache::quota::Limit { max_bytes: 1 << 30, every: Duration::from_secs(600) };
    let trimmed = sylva::cache::quota::trim_if_due(&backend, &one, limit).unwrap();
    assert!(trimmed.is_some_and(|p| p.trimmed == (0, 0)), "an empty cache within its bound");
    assert!(sylva::cache::quota::trim_if_due(&backend, &other, limit).unwrap().is_none(), "one trim per interval");
    let mut conn = ::redis::Client::open(redis.url.as_str()).unwrap().get_connection().unwrap();
    let ttl: i64 = ::redis::cmd("PTTL").arg("sylva:lock:trim").query(&mut conn).unwrap();
    assert!((590_000..=600_000).contains(&ttl), "left to expire an interval after the trim: {ttl} ms");

    let lock = one.try_lock("v0123456789abcdef/dem/1/0/0_0.bil", Duration::from_secs(5)).unwrap().unwrap();
    assert!(one.renew(&lock, Duration::from_secs(60)).unwrap());
    let ttl: i64 = ::redis::cmd("PTTL").arg(format!("sylva:lock:{}", lock.key)).query(&mut conn).unwrap();
    assert!(ttl > 50_000, "renewed to a minute: {ttl} ms");
    let stranger = sylva::cache::Lock { key: lock.key.clone(), token: "another holder".into() };
    assert!(!other.renew(&stranger, Duration::from_secs(60)).unwrap());
}
