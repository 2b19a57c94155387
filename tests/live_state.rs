//! The state file is rewritten every cycle: a dry run replaying a log as fast as the loop
//! computes (hundreds of cycles a second) while the kernel reports every file created in or
//! moved into the state file's folder (inotify `IN_CREATE`, `IN_MOVED_TO`: the rename that
//! replaces the state file). The
//! renames onto `state.json` must number exactly the cycles the store logged, and the file left
//! must be the last logged cycle's. A writer that skipped a cycle's state (throttled, or
//! keeping only the newest while the disk is busy) would count fewer.

mod live_support;
use live_support::*;
use rustix::fs::inotify;

#[test]
fn every_cycle_rewrites_the_state_file() {
    let dir = scratch();
    let d = dir.path();
    // 2 h of a row every 10 s: 721 cycles, replayed flat out.
    let rows = synth_replay(d, &["--hours", "2", "--period-s", "10", "--campaign", "2"]);
    std::fs::write(d.join("log.csv"), rows.join("\n") + "\n").unwrap();
    std::fs::write(
        d.join("live.toml"),
        config(
            "period_ms = 10000\nreplay_speed = 0",
            "timeout_ms = 15000\nramp_timeout_ms = 60000",
            "limit_um = 60\nslope_limit_um_per_m = 120\nrate_limit_um_s = 1.0",
            "",
        ),
    )
    .unwrap();
    let out = d.join("out");
    std::fs::create_dir(&out).unwrap();

    // The kernel queues up to fs.inotify.max_queued_events (16 384 by default) events; the
    // queue is read after the run, and an overflow would be reported as such. It merges an
    // unread event into an identical one before it, so the creations of the temporary file
    // are watched too: they stand between the renames.
    let fd = inotify::init(inotify::CreateFlags::NONBLOCK | inotify::CreateFlags::CLOEXEC).unwrap();
    inotify::add_watch(
        &fd,
        &out,
        inotify::WatchFlags::MOVED_TO | inotify::WatchFlags::CREATE,
    )
    .unwrap();

    let o = run(
        &[
            "live",
            "live.toml",
            "--dry-run",
            "--state",
            "out/state.json",
        ],
        d,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let mut renames = 0usize;
    let mut buf = vec![std::mem::MaybeUninit::<u8>::uninit(); 64 * 1024];
    let mut reader = inotify::Reader::new(&fd, &mut buf);
    loop {
        match reader.next() {
            Ok(e) => {
                assert!(
                    !e.events().contains(inotify::ReadFlags::QUEUE_OVERFLOW),
                    "the inotify queue overflowed"
                );
                if e.events().contains(inotify::ReadFlags::MOVED_TO)
                    && e.file_name().is_some_and(|n| n.to_bytes() == b"state.json")
                {
                    renames += 1;
                }
            }
            Err(rustix::io::Errno::AGAIN) => break,
            Err(e) => panic!("inotify: {e}"),
        }
    }

    let logged = cycles(&d.join("live.sqlite"));
    assert_eq!(logged.len(), rows.len() - 1, "one cycle per row");
    assert_eq!(
        renames,
        logged.len(),
        "the state file replaced once per logged cycle"
    );
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("state.json")).unwrap()).unwrap();
    assert_eq!(state["cycle"], logged.last().unwrap().cycle);
    assert_eq!(state["mode"], "stopped");
    // Nothing but the state file is left in its folder (the temporary file is renamed away).
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["state.json"]);
}
