// placeholder until the hal bench lands
fn main() {}
