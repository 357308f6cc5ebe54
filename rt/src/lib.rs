//! What nanopush's real-time loops (the server's control loop, the haptic bridge's device loop)
//! ask of Linux for their ticks to come on time: a core of their own and SCHED_FIFO. Each call acts
//! on the calling thread only (threads it starts afterwards inherit the result) and says whether
//! the system granted it; the caller decides what to log and whether to run on without it.
//!
//! ```no_run
//! let core = nanopush_rt::resolve_core(None); // the last online core
//! match nanopush_rt::pin_to_core(Some(core)) {
//!     Ok(core) => eprintln!("pinned to core {core}"),
//!     Err(e) => eprintln!("not pinned to core {core}: {e}"),
//! }
//! if let Err(e) = nanopush_rt::sched_fifo(45) {
//!     eprintln!("SCHED_FIFO refused: {e}");
//! }
//! ```
#![deny(missing_docs)]

use std::io;

/// The number of online CPUs (`sysconf(_SC_NPROCESSORS_ONLN)`), at least 1.
pub fn online_cpus() -> usize {
    // SAFETY: sysconf with a valid name has no preconditions.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    n.max(1) as usize
}

/// The core [`pin_to_core`] pins to for `cpu`: `cpu` itself, the last online core when it is
/// beyond them, and the last online core for `None`.
pub fn resolve_core(cpu: Option<usize>) -> usize {
    let last = online_cpus() - 1;
    cpu.unwrap_or(last).min(last)
}

/// Pins the calling thread to one core ([`resolve_core`] of `cpu`: `None` is the last online
/// core, a core beyond them is clamped to the last); the core pinned to, or the OS error of
/// `sched_setaffinity` (e.g. `EINVAL` when the process's cpuset excludes the core).
pub fn pin_to_core(cpu: Option<usize>) -> Result<usize, io::Error> {
    let core = resolve_core(cpu);
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET stays within it (core <
    // online_cpus() <= CPU_SETSIZE on any machine this runs on, and CPU_SET checks the bound);
    // sched_setaffinity(0, …) acts on the calling thread with a set of the size passed.
    let r = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(core, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    if r == 0 {
        Ok(core)
    } else {
        Err(io::Error::last_os_error())
    }
}

/// Runs the calling thread SCHED_FIFO at `priority` (1 to 99, higher first); the OS error
/// when refused (`EPERM` without `CAP_SYS_NICE` or an RLIMIT_RTPRIO that allows it, `EINVAL`
/// for a priority out of range). The thread keeps its policy on an error.
pub fn sched_fifo(priority: i32) -> Result<(), io::Error> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: pthread_self() is the calling thread, alive; `param` is initialized.
    let r = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    // pthread functions return the error number rather than setting errno.
    if r == 0 {
        Ok(())
    } else {
        Err(io::Error::from_raw_os_error(r))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `f` on a thread of its own, so that its affinity and policy stay there.
    fn on_a_thread<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
        std::thread::spawn(f).join().expect("the test thread")
    }

    /// The calling thread's allowed cores, from `sched_getaffinity`.
    fn affinity() -> Vec<usize> {
        // SAFETY: a zeroed cpu_set_t is valid; sched_getaffinity fills it for the calling thread.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            let r = libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
            assert_eq!(r, 0, "sched_getaffinity: {}", io::Error::last_os_error());
            (0..libc::CPU_SETSIZE as usize)
                .filter(|&c| libc::CPU_ISSET(c, &set))
                .collect()
        }
    }

    /// The calling thread's policy and priority, from `pthread_getschedparam`.
    fn policy() -> (i32, i32) {
        let mut policy = 0;
        // SAFETY: a zeroed sched_param is valid; both out-pointers point at locals.
        let param = unsafe {
            let mut param: libc::sched_param = std::mem::zeroed();
            let r = libc::pthread_getschedparam(libc::pthread_self(), &mut policy, &mut param);
            assert_eq!(r, 0, "pthread_getschedparam: {}", io::Error::from_raw_os_error(r));
            param
        };
        (policy, param.sched_priority)
    }

    /// `/sys/devices/system/cpu/online` ("0-1", "0,2-3"), counted.
    fn online_from_sysfs() -> usize {
        let text = std::fs::read_to_string("/sys/devices/system/cpu/online").expect("the online CPUs");
        text.trim()
            .split(',')
            .map(|r| match r.split_once('-') {
                Some((a, b)) => b.parse::<usize>().unwrap() - a.parse::<usize>().unwrap() + 1,
                None => 1,
            })
            .sum()
    }

    #[test]
    fn online_cpus_counts_the_cores_sysfs_lists_online() {
        assert_eq!(online_cpus(), online_from_sysfs());
    }

    #[test]
    fn none_is_the_last_online_core_and_a_core_beyond_them_is_clamped_to_it() {
        let last = online_cpus() - 1;
        assert_eq!(resolve_core(None), last);
        assert_eq!(resolve_core(Some(last + 1000)), last);
        assert_eq!(resolve_core(Some(0)), 0);
    }

    /// Pinned to the first core the process may run on, the thread may run there and nowhere
    /// else, as read back with `sched_getaffinity`; `None` pins to the last online core.
    #[test]
    fn a_pinned_thread_reads_back_one_core_in_its_affinity() {
        let (first, pinned, after) = on_a_thread(|| {
            let first = affinity()[0];
            let pinned = pin_to_core(Some(first));
            (first, pinned.map_err(|e| e.to_string()), affinity())
        });
        assert_eq!(pinned, Ok(first));
        assert_eq!(after, vec![first]);
        let (allowed, pinned, after) = on_a_thread(|| {
            let allowed = affinity();
            (allowed, pin_to_core(None), affinity())
        });
        let last = online_cpus() - 1;
        match pinned {
            Ok(core) => {
                assert_eq!(core, last);
                assert_eq!(after, vec![last]);
            }
            // Refused only when the process may not run on the last core, with the OS's reason.
            Err(e) => {
                assert!(!allowed.contains(&last), "{e}");
                assert_eq!(e.raw_os_error(), Some(libc::EINVAL), "{e}");
                assert_eq!(after, allowed, "a refusal leaves the affinity as it was");
            }
        }
    }

    /// Granted, the policy read back is SCHED_FIFO at the priority asked for (and SCHED_OTHER
    /// is restored after); refused, the error is the OS's (`EPERM`) and the policy unchanged.
    #[test]
    fn sched_fifo_is_read_back_when_granted_or_refused_with_the_os_error() {
        let (result, during, restored) = on_a_thread(|| {
            let result = sched_fifo(10);
            let during = policy();
            let other = libc::sched_param { sched_priority: 0 };
            // SAFETY: as in `sched_fifo`.
            let r = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_OTHER, &other) };
            assert_eq!(r, 0, "restoring SCHED_OTHER");
            (result, during, policy())
        });
        match result {
            Ok(()) => assert_eq!(during, (libc::SCHED_FIFO, 10)),
            Err(e) => {
                assert_eq!(e.raw_os_error(), Some(libc::EPERM), "{e}");
                assert_eq!(during.0, libc::SCHED_OTHER);
            }
        }
        assert_eq!(restored, (libc::SCHED_OTHER, 0));
    }

    /// A priority outside 1-99 is refused with `EINVAL`, the error number pthread returns (not
    /// a stale `errno`), and the thread's policy is left alone.
    #[test]
    fn a_priority_out_of_range_is_refused_with_einval() {
        let (result, after) = on_a_thread(|| (sched_fifo(100), policy()));
        let e = result.expect_err("priority 100 is out of range");
        assert_eq!(e.raw_os_error(), Some(libc::EINVAL), "{e}");
        assert_eq!(after, (libc::SCHED_OTHER, 0));
    }
}
