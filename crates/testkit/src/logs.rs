//! The log lines a piece of code writes through `tracing`, for the tests
//! that check what the journal is told (and how often).

use std::io::{self, Write};
use std::sync::{Arc, Mutex};

/// The log lines (INFO and above, plain text as the daemon's fmt layer
/// writes them, no colours) written while `f` runs on this thread.
pub fn logged(f: impl FnOnce()) -> String {
    #[derive(Clone)]
    struct Capture(Arc<Mutex<Vec<u8>>>);
    impl Write for Capture {
        fn write(&mut self, b: &[u8]) -> io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }
    let cap = Capture(Arc::default());
    let out = cap.clone();
    let sub = tracing_subscriber::fmt()
        .with_ansi(false)
        .with_max_level(tracing::Level::INFO)
        .with_writer(move || out.clone())
        .finish();
    tracing::subscriber::with_default(sub, f);
    let text = cap.0.lock().unwrap().clone();
    String::from_utf8(text).unwrap()
}
