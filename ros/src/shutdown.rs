//! Clean shutdown on SIGINT and SIGTERM: a shared flag that every node loop checks.
//!
//! The first signal sets the flag, so loops finish their current step, close bags and return; a
//! second signal exits immediately with status 130, for a node stuck in shutdown.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use signal_hook::consts::signal::{SIGINT, SIGTERM};

/// A shutdown request flag, cheap to clone and share between loops and threads.
#[derive(Debug, Clone, Default)]
pub struct Shutdown {
    flag: Arc<AtomicBool>,
}

/// Installing the signal handlers failed.
#[derive(Debug, thiserror::Error)]
#[error("cannot install the SIGINT/SIGTERM handlers: {0}")]
pub struct ShutdownError(#[source] std::io::Error);

impl Shutdown {
    /// A flag set only by [`Shutdown::request`] (for tests and embedded use).
    pub fn manual() -> Shutdown {
        Shutdown::default()
    }

    /// A flag set by SIGINT or SIGTERM. A second signal exits the process with status 130.
    pub fn install() -> Result<Shutdown, ShutdownError> {
        let s = Shutdown::default();
        for sig in [SIGINT, SIGTERM] {
            // Registered first, so it sees the flag before this signal sets it: exits only on
            // the second signal.
            signal_hook::flag::register_conditional_shutdown(sig, 130, Arc::clone(&s.flag))
                .map_err(ShutdownError)?;
            signal_hook::flag::register(sig, Arc::clone(&s.flag)).map_err(ShutdownError)?;
        }
        Ok(s)
    }

    /// Whether shutdown has been requested.
    pub fn requested(&self) -> bool {
        self.flag.load(Ordering::SeqCst)
    }

    /// Requests shutdown.
    pub fn request(&self) {
        self.flag.store(true, Ordering::SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_request_is_seen_by_clones() {
        let s = Shutdown::manual();
        let c = s.clone();
        assert!(!c.requested());
        s.request();
        assert!(c.requested());
    }
}
