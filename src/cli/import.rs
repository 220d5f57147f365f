//! `hybc import FILE.xml [-o FILE.hyb]`: an SBML document translated to a `.hyb` text
//! (`crate::import_sbml_file`), checked as a model before it is written, so that what is written
//! compiles. Standard output without `-o` (or with `-o -`).

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use super::{error_chain, output, EXIT_MODEL_ERROR, EXIT_USAGE_ERROR};

#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    /// The SBML file (Level 2 or 3).
    pub file: PathBuf,
    /// Where to write the .hyb model (`-`: standard output, the default).
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    pub output: Option<PathBuf>,
}

pub fn run(args: &ImportArgs) -> ExitCode {
    let import = match crate::import_sbml_file(&args.file) {
        Ok(i) => i,
        Err(crate::Error::Import(e)) => {
            eprint!("{e}");
            return ExitCode::from(EXIT_MODEL_ERROR);
        }
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            return ExitCode::from(EXIT_USAGE_ERROR);
        }
    };
    // The text is checked before it is written: an import that does not check is a bug of the
    // importer, reported rather than handed on.
    let name = format!("{} (imported)", args.file.display());
    if let Err(e) = crate::Model::parse_named(&import.text, &name) {
        eprintln!("error: {}", error_chain(&e));
        return ExitCode::from(EXIT_MODEL_ERROR);
    }
    let path = args.output.clone().unwrap_or_else(|| PathBuf::from(output::STDOUT));
    let written = output::create(&path).and_then(|mut out| {
        out.write_all(import.text.as_bytes())?;
        out.flush()
    });
    match output::closed_pipe_is_done(&path, written) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: cannot write `{}`: {e}", path.display());
            ExitCode::from(EXIT_USAGE_ERROR)
        }
    }
}
