// The library example of docs/cli.md, verbatim: an outside crate that depends on hybc without its
// default features (no CLI, no plots). `.ci/run` builds it and checks that it prints the numbers
// `hybc run models/ball.hyb --set e=0.9 --grad e,h0 --format json` prints (run it from the
// repository root).
use hybc::{Error, Model};

fn main() -> Result<(), Error> {
    let text = std::fs::read_to_string("models/ball.hyb").expect("readable model");
    let model = Model::parse(&text)?; // syntax and checks; the error renders diagnostics
    let compiled = model.compile(&["e", "h0"])?; // JIT, gradients with respect to e and h0
    let mut params = model.params(); // the model's default values, by name
    params.set("e", 0.9)?; // range-checked; an unknown name is an error
    let opts = model.sim_options(); // the model's `simulate` line over hybc run's defaults
    let run = compiled.simulate(&params, &opts)?;
    for ev in run.events() {
        println!("{}", ev.time);
    }
    println!("{:?} {:?}", run.output("energy"), run.doutput("energy", "e")); // Option<f64>
    let shared: hybc::Compiled = compiled.clone(); // cheap; Send + Sync + 'static
    std::thread::spawn(move || shared.simulate(&params, &opts).map(|r| r.output("energy")))
        .join()
        .expect("thread")?;
    Ok(())
}
