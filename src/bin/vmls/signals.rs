//! Stop requests: SIGINT (Ctrl-C), SIGTERM (`kill`, `timeout`, a batch system) and SIGHUP (a
//! closed terminal) are handled alike, so that none leaves an output's temporary behind.
//!
//! For a command that can stop between submissions (`render`), the first signal sets the stop
//! flag (the frame ends after the dispatch in flight and nothing is written) and a second one
//! removes every temporary output and exits at once, as does [`GRACE`] passing without a stop:
//! host work that reads no flag (an octree build, a `--cpu` frame) or a hung process must not
//! outlive a `timeout` or a batch system's SIGTERM. Every other command removes its
//! temporaries and exits at the first signal. The exit status is 128 + the first signal's
//! number (130, 143, 129), as a shell reports a process killed by it.

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

/// How long a graceful stop may take before the process quits anyway.
pub const GRACE: std::time::Duration = std::time::Duration::from_secs(10);

/// The first stop signal received; 0 while none was.
static FIRST: AtomicI32 = AtomicI32::new(0);

fn name(signal: i32) -> &'static str {
    match signal {
        SIGINT => "interrupted (SIGINT)",
        SIGTERM => "terminated (SIGTERM)",
        SIGHUP => "hung up (SIGHUP)",
        _ => "stopped by a signal",
    }
}

/// The exit status of a command that ended on a stop request: 128 + the first signal.
pub fn exit_status() -> i32 {
    128 + match FIRST.load(Ordering::SeqCst) {
        0 => SIGINT,
        s => s,
    }
}

/// Installs the handlers (see the module contract) and returns the stop flag. Without them
/// (registration failed) the signals keep their default: exit at once.
pub fn install(graceful: bool) -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let seen = flag.clone();
    if let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) {
        std::thread::spawn(move || {
            for signal in signals.forever() {
                let _ = FIRST.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
                // Writes to stderr may fail (a closed terminal after SIGHUP): never panic here,
                // or the thread dies and no later signal is handled.
                let say = move |text: String| {
                    let _ = writeln!(std::io::stderr(), "vmls: {}: {text}", name(signal));
                };
                if !graceful || seen.swap(true, Ordering::SeqCst) {
                    vmls::files::remove_temporaries();
                    say("quit without writing".into());
                    std::process::exit(exit_status());
                }
                say("stopping without writing (Ctrl-C again to quit at once)".into());
                std::thread::spawn(move || {
                    std::thread::sleep(GRACE);
                    vmls::files::remove_temporaries();
                    say(format!(
                        "did not stop within {} s: quit without writing",
                        GRACE.as_secs()
                    ));
                    std::process::exit(exit_status());
                });
            }
        });
    }
    flag
}
