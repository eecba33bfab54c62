use mvem::analysis::steady::steady_state;
use mvem::model::{Drive, Engine8};
fn main() {
    let m = Engine8::published();
    for d in [
        Drive::new(500.0, 1.0, 50.0, 65.0),
        Drive::new(1000.0, 1.0, 50.0, 65.0),
        Drive::new(1500.0, 110.0, 80.0, 75.0),
        Drive::new(1400.0, 245.0, 0.0, 35.0),
        Drive::new(2000.0, 200.0, 20.0, 40.0),
    ] {
        let s = steady_state(&m, &d).unwrap();
        println!(
            "{:?} flags {:?}\n   eig {:?}",
            d.to_array(),
            s.flags,
            s.eigenvalues
        );
    }
}
