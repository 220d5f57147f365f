//! Runs the `hybc` command on a generated model and measures its wall time and peak resident
//! memory, for the stress tests' bounds against blow-up.

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Runs `hybc args` on `model_text`, polling its peak resident memory (VmHWM); returns stdout,
/// stderr, the exit code, the wall time and the peak in MiB.
pub fn hybc_measured(model_text: &str, args: &[&str]) -> (String, String, Option<i32>, Duration, f64) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("stress.hyb");
    std::fs::File::create(&path).and_then(|mut f| f.write_all(model_text.as_bytes())).expect("write");
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_hybc"))
        .arg(args[0])
        .arg(&path)
        .args(&args[1..])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("hybc starts");
    let status_path = format!("/proc/{}/status", child.id());
    let mut peak_kib = 0u64;
    let (out, err) = {
        let mut stdout = child.stdout.take().expect("stdout");
        let mut stderr = child.stderr.take().expect("stderr");
        let out = std::thread::spawn(move || std::io::read_to_string(&mut stdout).unwrap_or_default());
        let err = std::thread::spawn(move || std::io::read_to_string(&mut stderr).unwrap_or_default());
        while child.try_wait().expect("wait").is_none() {
            if let Ok(status) = std::fs::read_to_string(&status_path) {
                if let Some(kib) = status
                    .lines()
                    .find_map(|l| l.strip_prefix("VmHWM:"))
                    .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
                {
                    peak_kib = peak_kib.max(kib);
                }
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        (out.join().expect("stdout reader"), err.join().expect("stderr reader"))
    };
    let code = child.wait().expect("exit").code();
    (out, err, code, started.elapsed(), peak_kib as f64 / 1024.0)
}

pub fn assert_bounded(what: &str, elapsed: Duration, peak_mib: f64, time_limit: Duration, mib_limit: f64) {
    eprintln!("{what}: {elapsed:.2?}, peak {peak_mib:.0} MiB");
    assert!(elapsed < time_limit, "{what} took {elapsed:?}");
    assert!(peak_mib < mib_limit, "{what} peaked at {peak_mib:.0} MiB");
}
