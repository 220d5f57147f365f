//! Where the command line's text goes. A path flag that writes (`run --trajectory`,
//! `--samples-out`, `sweep --output`, `sobol --design-out`) takes `-` for standard output; the
//! command's own report then goes to standard error, so that standard output holds nothing but
//! that file's text (docs/cli.md, "Standard output"). A closed standard output (`| head`) ends the
//! writing quietly: the reader has what it wanted.

use std::io::{self, BufWriter, Write};
use std::path::Path;

/// The path that stands for standard output.
pub(crate) const STDOUT: &str = "-";

/// Whether a path flag's value is `-`, standard output.
pub(crate) fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == STDOUT
}

/// A buffered writer to `path`, or to standard output for `-`.
pub(crate) fn create(path: &Path) -> io::Result<Box<dyn Write>> {
    Ok(if is_stdout(path) {
        Box::new(BufWriter::new(io::stdout()))
    } else {
        Box::new(BufWriter::new(std::fs::File::create(path)?))
    })
}

/// `written` (the outcome of writing to `path`), with a closed standard output taken as done.
pub(crate) fn closed_pipe_is_done(path: &Path, written: io::Result<()>) -> io::Result<()> {
    match written {
        Err(e) if is_stdout(path) && e.kind() == io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}

/// Standard output or standard error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Stream {
    Stdout,
    Stderr,
}

/// Where a command's report goes: standard error when one of `flags` (a flag's name and its
/// path) writes to standard output, else standard output. Two flags cannot share it.
pub(crate) fn report_stream(flags: &[(&str, Option<&Path>)]) -> Result<Stream, String> {
    let to_stdout: Vec<&str> =
        flags.iter().filter(|(_, path)| path.is_some_and(is_stdout)).map(|(flag, _)| *flag).collect();
    match to_stdout.as_slice() {
        [] => Ok(Stream::Stdout),
        [_] => Ok(Stream::Stderr),
        several => {
            Err(format!("{}: only one of them can write to standard output (`-`)", several.join(" and ")))
        }
    }
}

/// Lets `write` stream to `stream`, buffered; the first failed write ends the output (a closed
/// pipe is not an error worth a message).
pub(crate) fn write_to(stream: Stream, write: impl FnOnce(&mut dyn Write) -> io::Result<()>) {
    let _ = match stream {
        Stream::Stdout => {
            let mut out = BufWriter::new(io::stdout().lock());
            write(&mut out).and_then(|()| out.flush())
        }
        Stream::Stderr => {
            let mut out = BufWriter::new(io::stderr().lock());
            write(&mut out).and_then(|()| out.flush())
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_flag_may_take_standard_output_and_the_report_moves_aside() {
        let dash = Path::new("-");
        let file = Path::new("out.csv");
        assert_eq!(
            report_stream(&[("--trajectory", Some(file)), ("--samples-out", None)]),
            Ok(Stream::Stdout)
        );
        assert_eq!(
            report_stream(&[("--trajectory", Some(dash)), ("--samples-out", None)]),
            Ok(Stream::Stderr)
        );
        assert_eq!(
            report_stream(&[("--trajectory", Some(dash)), ("--samples-out", Some(dash))]),
            Err("--trajectory and --samples-out: only one of them can write to standard output (`-`)".into())
        );
        assert!(!is_stdout(Path::new("./-")));
    }
}
