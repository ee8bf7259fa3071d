//! Stopping the pipeline's processes (perturbd, the bridge) when they run as children of a tool
//! or a test: the one way they are asked to stop is SIGINT, which both handle by finishing their
//! report; a child that does not stop in time is killed.

use std::process::{Child, ExitStatus};
use std::time::{Duration, Instant};

/// Sends SIGINT to `child` and waits up to `grace` for it to exit; returns its exit status, or
/// `None` if it had to be killed (SIGKILL) after `grace`.
///
/// ```no_run
/// use std::time::Duration;
/// let mut child = std::process::Command::new("perturbd").spawn().unwrap();
/// match perturb_wire::process::interrupt(&mut child, Duration::from_secs(10)) {
///     Some(status) => println!("perturbd exited: {status}"),
///     None => eprintln!("perturbd did not stop within 10 s and was killed"),
/// }
/// ```
// libc's kill.
#[allow(unsafe_code)]
pub fn interrupt(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    if let Ok(Some(status)) = child.try_wait() {
        return Some(status);
    }
    // SAFETY: kill(2) on the pid of our own child, which has not been reaped (try_wait above
    // returned None), so the pid cannot have been reused.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let start = Instant::now();
    while start.elapsed() < grace {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::Command;

    /// `sleep 30` with SIGINT at its default action, whatever this process inherited (a test
    /// run started in the background of a shell has SIGINT ignored, and children inherit that).
    // libc's signal between fork and exec.
    #[allow(unsafe_code)]
    fn sleeper() -> std::process::Child {
        use std::os::unix::process::CommandExt;
        let mut cmd = Command::new("sleep");
        cmd.arg("30");
        // SAFETY: signal(2) is async-signal-safe, the only kind of call allowed between fork and
        // exec.
        unsafe {
            cmd.pre_exec(|| {
                libc::signal(libc::SIGINT, libc::SIG_DFL);
                Ok(())
            });
        }
        cmd.spawn().unwrap()
    }

    #[test]
    fn a_child_that_heeds_sigint_exits_and_one_that_ignores_it_is_killed() {
        let mut sleeper = sleeper();
        let st = interrupt(&mut sleeper, Duration::from_secs(5)).expect("sleep dies on SIGINT");
        assert!(!st.success());
        let mut stubborn = Command::new("sh")
            .args(["-c", "trap '' INT; echo ready; exec sleep 30"])
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // Only once the shell ignores SIGINT (the ignored disposition survives the exec).
        let mut line = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(stubborn.stdout.take().unwrap()),
            &mut line,
        )
        .unwrap();
        assert_eq!(line.trim(), "ready");
        let t = Instant::now();
        assert_eq!(interrupt(&mut stubborn, Duration::from_millis(300)), None);
        assert!(t.elapsed() < Duration::from_secs(5));
        assert!(stubborn.try_wait().unwrap().is_some(), "killed and reaped");
    }
}
