fn main() {
    let path = std::env::args().nth(1).unwrap();
    match hybc::sbml::import(&std::fs::read_to_string(&path).unwrap()) {
        Ok(i) => print!("{}", i.text),
        Err(e) => print!("{}", e.render(&path)),
    }
}
