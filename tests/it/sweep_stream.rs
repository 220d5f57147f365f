//! Streamed sweeps (`hybc::sweep::stream_rows`, `hybc sweep`): rows are written in input order as
//! they complete, byte for byte what the in-memory sweep of hybc 0.x wrote (files in
//! tests/data/sweep, written by the build before streaming; rewritten by `hybc sweep --threads 1`
//! when the error norm became one per block, issue #25 item 5, which moved the values by about
//! 1e-14, and when Zeno became a rule on the event sequence, issue #37 item 1.3, which stops the
//! Zeno points at fewer bounces, and when events late by a spacing of `t` were applied at their
//! crossings, issue #37's model 779, which moved the last Zeno bounces by an ulp), for any thread count, and with a peak
//! memory that does not grow with the number of points.

use crate::support::cli::hybc;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use hybc::sim::SimOptions;
use hybc::sweep::{self, Axis, Columns, Draws, Format, Grid, Points};

fn sweep_bytes(args: &[&str], threads: &str) -> Vec<u8> {
    let mut all = vec!["sweep"];
    all.extend_from_slice(args);
    all.extend(["--threads", threads]);
    let out = hybc(&all);
    // Both files hold Zeno points: exit 3 after every row.
    assert_eq!(out.status.code(), Some(3), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    out.stdout
}

#[test]
fn rows_are_the_bytes_the_in_memory_sweep_wrote_for_any_thread_count() {
    let grid: &[&str] = &[
        "models/ball.hyb",
        "--vary",
        "e=0.6:0.95:12",
        "--vary",
        "h0=0.5,1,4",
        "--grad",
        "all",
        "--events",
        "3",
        "--t-end",
        "6",
    ];
    let samples: &[&str] = &[
        "models/ball.hyb",
        "--samples",
        "40",
        "--seed",
        "9",
        "--vary",
        "e",
        "--vary",
        "h0=0.5:2",
        "--grad",
        "e",
        "--t-end",
        "10",
        "--format",
        "jsonl",
    ];
    let before_grid = include_bytes!("../data/sweep/ball_grid.csv");
    let before_samples = include_bytes!("../data/sweep/ball_samples.jsonl");
    for threads in ["1", "4"] {
        assert!(sweep_bytes(grid, threads) == before_grid, "grid with {threads} threads");
        assert!(sweep_bytes(samples, threads) == before_samples, "samples with {threads} threads");
    }
}

const DECAY: &str =
    "model decay\nparam k = 1 in [0, 10]\nstate x = 1\nder(x) = -k * x\noutput half = x / 2\n\
                     simulate t_end = 0.01, rtol = 1e-3, atol = 1e-6\n";

#[test]
fn the_library_stream_writes_what_the_in_memory_sweep_writes() {
    // More points than the reorder window holds, so workers wait for the writer.
    let n = sweep::WINDOW_ROWS + 1000;
    let model = hybc::Model::parse(DECAY).expect("model");
    let compiled = model.compile(&["k"]).expect("compiles");
    let opts = SimOptions { t_end: 0.01, rtol: 1e-3, atol: 1e-6, ..SimOptions::default() };
    let columns = Columns::new(compiled.info(), 1, 1);
    let grid =
        Points::Grid(Grid::new(vec![1.0], vec![(0, Axis::Even { lo: 0.0, hi: 10.0, n })]).expect("grid"));
    let samples = Points::Draws(Draws::new(vec![1.0], vec![(0, 0.0, 10.0)], n, 3));
    for points in [grid, samples] {
        let held = points.to_vec();
        let results = sweep::run_points(compiled.native(), &held, &opts, 2, &|| ()).expect("pool");
        let mut expected = Vec::new();
        sweep::write_rows(&mut expected, &columns, Format::Csv, &held, &results, 2).expect("written");
        for threads in [1, 4] {
            let mut streamed = Vec::new();
            let done = sweep::stream_rows(
                compiled.native(),
                &points,
                &opts,
                &columns,
                Format::Csv,
                threads,
                false,
                &|| (),
                &mut streamed,
            )
            .expect("streamed");
            assert_eq!((done.rows, done.ended_early), (n, 0));
            assert!(streamed == expected, "{threads} threads");
        }
    }
}

/// Runs `hybc` with `args` and returns its exit code, wall time and peak resident memory
/// (`VmHWM` of /proc/PID/status, read every 5 ms while it runs: the high-water mark only grows,
/// so the last reading is the peak up to a few ms before the exit).
fn run_measured(args: &[&str]) -> (Option<i32>, Duration, u64) {
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_hybc"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("hybc starts");
    let status_path = format!("/proc/{}/status", child.id());
    let mut peak_kib = 0;
    let status = loop {
        if let Ok(text) = std::fs::read_to_string(&status_path) {
            let hwm = text
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok());
            peak_kib = peak_kib.max(hwm.unwrap_or(0));
        }
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    (status.code(), started.elapsed(), peak_kib)
}

#[test]
fn peak_memory_does_not_grow_with_the_number_of_points() {
    let dir = tempfile::tempdir().expect("temp dir");
    let model = dir.path().join("decay.hyb");
    std::fs::write(&model, DECAY).expect("model written");
    let model = model.to_str().expect("utf-8 path");
    let measure = |n: usize| {
        let out = dir.path().join(format!("rows{n}.csv"));
        let vary = format!("k=0:10:{n}");
        let args = [
            "sweep",
            model,
            "--vary",
            &vary,
            "--grad",
            "k",
            "--threads",
            "2",
            "-o",
            out.to_str().expect("path"),
        ];
        let (code, wall, peak_kib) = run_measured(&args);
        assert_eq!(code, Some(0), "{n} points");
        let rows = std::fs::read_to_string(&out).expect("rows").lines().count();
        assert_eq!(rows, n + 1, "header and one row per point");
        (wall, peak_kib)
    };
    // Held in memory (hybc before streaming), the 10^6 results of this model peaked at 519 MB;
    // streamed, about 10 MB at any count (a few seconds in a debug build).
    let (small_wall, small) = measure(2_000);
    let (large_wall, large) = measure(1_000_000);
    eprintln!(
        "2 000 points: {small_wall:?}, peak {} MiB; 1 000 000 points: {large_wall:?}, peak {} MiB",
        small / 1024,
        large / 1024
    );
    assert!(large < small + 32 * 1024, "peak {large} KiB at 10^6 points, {small} KiB at 2 000");
    assert!(large < 128 * 1024, "peak {large} KiB at 10^6 points");
    assert!(large_wall < Duration::from_secs(300), "{large_wall:?}");
}

#[test]
fn a_reader_that_stops_early_stops_the_sweep() {
    // `hybc sweep ... | head -2`: the rows are written as they complete, so a closed pipe ends the
    // sweep at once (exit 0: the reader has what it wanted) instead of after 10^7 runs.
    use std::io::{BufRead as _, BufReader};
    let dir = tempfile::tempdir().expect("temp dir");
    let model = dir.path().join("decay.hyb");
    std::fs::write(&model, DECAY).expect("model written");
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_hybc"))
        .args(["sweep", model.to_str().expect("path"), "--vary", "k=0:10:10000000", "--threads", "2"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("hybc starts");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    assert_eq!(
        lines.next().expect("header").expect("text"),
        "k,status,events,event1,t1,event2,t2,event3,t3,event4,t4,event5,t5,t_final,x,half,error"
    );
    assert!(lines.next().expect("row").expect("text").starts_with("0,ok,0,"));
    drop(lines);
    let status = child.wait().expect("exits");
    assert_eq!(status.code(), Some(0));
    assert!(started.elapsed() < Duration::from_secs(60), "{:?}", started.elapsed());
}
