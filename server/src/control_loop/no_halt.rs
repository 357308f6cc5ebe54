//! Keeps the control loop's core polling instead of halting while the loop runs.
//!
//! Why: between two ticks the loop sleeps about 0.9 ms and its core has nothing else to run,
//! so the kernel halts it. A halted virtual CPU runs again only when the hypervisor delivers its
//! timer interrupt, which can come milliseconds late when the other core is busy: the tick
//! overruns although its work takes microseconds. A polling core (the cpuidle `POLL` state: it
//! spins in the kernel, checking for work) wakes on time. On bare metal the same setting keeps
//! the core out of deep C-states, whose exit latency (tens to hundreds of µs) would otherwise
//! come on top of a tick's wake-up.
//!
//! Only the loop's core: the system-wide request (`/dev/cpu_dma_latency` = 0, as `cyclictest`
//! holds it) makes every core poll, which takes the host's time from the other vCPU and overran
//! more. The traces and the soaks that chose between the three regimes are in
//! `docs/benchmarks.md` ("Soak"; `nanopush-soak 600 --alternate 20` repeats them).
//!
//! The setting is the core's PM QoS resume latency,
//! `/sys/devices/system/cpu/cpuN/power/pm_qos_resume_latency_us`: `n/a` means 0 µs, and the
//! cpuidle governor then picks only the polling state (`0` means no constraint, the default).
//! Unlike the system-wide request it is not withdrawn when the process dies, so what it was
//! before is kept in a record, `/run/nanopush/no-halt-cpuN`: the value to restore and the pid
//! of each server holding it, under an exclusive `flock`. The last holder to end restores the
//! value; a holder that died (kill -9) is dropped from the record by the next server that starts
//! or ends, and the value is restored when no live holder is left. `/run` is a tmpfs, cleared at
//! boot like the setting itself. The price: the core spins while idle (power and heat on a lab PC,
//! a busy virtual CPU for a hypervisor); `nanopush serve --allow-cpu-halt` leaves it out.

use std::io::{Read as _, Seek as _, Write as _};
use std::os::fd::AsRawFd as _;
use std::path::{Path, PathBuf};

/// Where the records live.
pub const RECORD_DIR: &str = "/run/nanopush";

/// The setting's value that means 0 µs: poll, never halt.
pub const POLL: &str = "n/a";

/// The PM QoS resume latency of core `cpu`.
pub fn setting_path(cpu: usize) -> PathBuf {
    PathBuf::from(format!(
        "/sys/devices/system/cpu/cpu{cpu}/power/pm_qos_resume_latency_us"
    ))
}

/// The record of core `cpu`'s holders.
pub fn record_path(cpu: usize) -> PathBuf {
    Path::new(RECORD_DIR).join(format!("no-halt-cpu{cpu}"))
}

/// Why the core could not be kept polling (or restored).
#[derive(Debug, thiserror::Error)]
#[error("{what} {path}: {source}")]
pub struct NoHaltError {
    /// What was being done.
    what: &'static str,
    /// The file.
    path: PathBuf,
    /// Cause.
    source: std::io::Error,
}

fn io<T>(what: &'static str, path: &Path, r: std::io::Result<T>) -> Result<T, NoHaltError> {
    r.map_err(|source| NoHaltError {
        what,
        path: path.to_path_buf(),
        source,
    })
}

/// A live server's pid: its process exists, is named `nanopush` (a pid recycled for another
/// program, the haptic bridge `nanopush-haptic` included, is not) and is not a zombie.
pub fn is_live_server(pid: u32) -> bool {
    is_live_named(pid, "nanopush")
}

/// Whether process `pid` exists, is named `name` (its `comm`) and is not a zombie.
fn is_live_named(pid: u32, name: &str) -> bool {
    let named = std::fs::read_to_string(format!("/proc/{pid}/comm")).is_ok_and(|c| c.trim_end() == name);
    // The state follows the command name's closing parenthesis in /proc/PID/stat.
    let zombie = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map(|s| {
            s.rsplit_once(')')
                .is_some_and(|(_, rest)| rest.trim_start().starts_with(['Z', 'X']))
        })
        .unwrap_or(true);
    named && !zombie
}

/// The record's contents: the setting's value before the first holder, and the holders.
#[derive(Debug, Clone, Default, PartialEq)]
struct Record {
    original: Option<String>,
    holders: Vec<u32>,
}

impl Record {
    fn parse(text: &str) -> Record {
        let mut r = Record::default();
        for line in text.lines() {
            match line.split_once(' ') {
                Some(("original", v)) if !v.trim().is_empty() => r.original = Some(v.trim().to_string()),
                Some(("holder", p)) => r.holders.extend(p.trim().parse::<u32>().ok()),
                _ => {}
            }
        }
        r
    }

    fn render(&self) -> String {
        match &self.original {
            None => String::new(),
            Some(o) => {
                let mut s = format!("original {o}\n");
                for p in &self.holders {
                    s.push_str(&format!("holder {p}\n"));
                }
                s
            }
        }
    }
}

/// The record file, locked (`flock`, exclusive) until dropped. It is never removed (an empty
/// file means no holder): a server waiting for the lock holds the same file as the one that
/// releases it.
struct Locked {
    file: std::fs::File,
    path: PathBuf,
}

impl Locked {
    fn open(path: &Path) -> Result<Locked, NoHaltError> {
        if let Some(dir) = path.parent() {
            io("creating", dir, std::fs::create_dir_all(dir))?;
        }
        let file = io(
            "opening",
            path,
            std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(path),
        )?;
        // SAFETY: flock on a file descriptor this function owns; it blocks until granted.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) } != 0 {
            return Err(NoHaltError {
                what: "locking",
                path: path.to_path_buf(),
                source: std::io::Error::last_os_error(),
            });
        }
        Ok(Locked {
            file,
            path: path.to_path_buf(),
        })
    }

    fn read(&mut self) -> Result<Record, NoHaltError> {
        let mut text = String::new();
        io("reading", &self.path, self.file.read_to_string(&mut text))?;
        Ok(Record::parse(&text))
    }

    fn write(&mut self, r: &Record) -> Result<(), NoHaltError> {
        let path = self.path.clone();
        io("rewinding", &path, self.file.rewind())?;
        io("truncating", &path, self.file.set_len(0))?;
        io("writing", &path, self.file.write_all(r.render().as_bytes()))
    }
}

fn read_setting(path: &Path) -> Result<String, NoHaltError> {
    Ok(io("reading", path, std::fs::read_to_string(path))?.trim().to_string())
}

fn write_setting(path: &Path, value: &str) -> Result<(), NoHaltError> {
    io("writing", path, std::fs::write(path, value))
}

/// Core polling, held: dropping it gives the core back (the last holder restores its setting).
#[derive(Debug)]
pub struct NoHalt {
    setting: PathBuf,
    record: PathBuf,
    pid: u32,
    alive: fn(u32) -> bool,
}

impl NoHalt {
    /// Keeps core `cpu` polling for this process. Fails where the setting is missing (no
    /// cpuidle, a container) or not writable (it is root's), or the record cannot be kept.
    pub fn request(cpu: usize) -> Result<NoHalt, NoHaltError> {
        NoHalt::request_at(
            &setting_path(cpu),
            &record_path(cpu),
            std::process::id(),
            is_live_server,
        )
    }

    /// [`NoHalt::request`] with its files, its holder's pid and the liveness test given.
    pub fn request_at(setting: &Path, record: &Path, pid: u32, alive: fn(u32) -> bool) -> Result<NoHalt, NoHaltError> {
        let mut lock = Locked::open(record)?;
        let mut r = lock.read()?;
        let dead: Vec<u32> = r.holders.iter().copied().filter(|&p| !alive(p)).collect();
        if !dead.is_empty() {
            tracing::info!(
                "{}: dropping holders that ended without giving the core back: {dead:?}",
                record.display()
            );
        }
        r.holders.retain(|&p| alive(p) && p != pid);
        // A record left by holders that died keeps the value from before them.
        let original = match r.original.take() {
            Some(o) => o,
            None => read_setting(setting)?,
        };
        let alone = r.holders.is_empty();
        write_setting(setting, POLL)?;
        r.original = Some(original.clone());
        r.holders.push(pid);
        if let Err(e) = lock.write(&r) {
            // Without a record nobody would restore it: give the core back now.
            if alone {
                let _ = write_setting(setting, &original);
            }
            return Err(e);
        }
        Ok(NoHalt {
            setting: setting.to_path_buf(),
            record: record.to_path_buf(),
            pid,
            alive,
        })
    }

    /// Removes this holder (and any dead one); the last restores the setting.
    fn release(&self) -> Result<(), NoHaltError> {
        let mut lock = Locked::open(&self.record)?;
        let mut r = lock.read()?;
        r.holders.retain(|&p| p != self.pid && (self.alive)(p));
        if r.holders.is_empty() {
            if let Some(o) = &r.original {
                write_setting(&self.setting, o)?;
            }
            r = Record::default();
        }
        lock.write(&r)
    }
}

impl Drop for NoHalt {
    fn drop(&mut self) {
        if let Err(e) = self.release() {
            tracing::warn!("giving the loop's core back (it may keep polling): {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stand-ins for the sysfs setting and the record, in a fresh directory.
    fn place(tag: &str, value: &str) -> (PathBuf, PathBuf) {
        let dir = std::env::temp_dir().join(format!("nanopush-no-halt-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let setting = dir.join("pm_qos_resume_latency_us");
        std::fs::write(&setting, format!("{value}\n")).unwrap();
        std::fs::create_dir_all(dir.join("run")).unwrap();
        (setting, dir.join("run/no-halt-cpu1"))
    }

    fn text(p: &Path) -> String {
        std::fs::read_to_string(p).unwrap()
    }

    /// Pids below 1000 are live in these tests; 4242 is a holder that died.
    fn below_1000(pid: u32) -> bool {
        pid < 1000
    }

    #[test]
    fn a_holder_sets_poll_and_restores_the_value_it_found() {
        let (setting, record) = place("one", "0");
        let held = NoHalt::request_at(&setting, &record, 7, below_1000).unwrap();
        assert_eq!(text(&setting), "n/a");
        assert_eq!(text(&record), "original 0\nholder 7\n");
        drop(held);
        assert_eq!(text(&setting), "0");
        assert_eq!(text(&record), "", "the record stays, empty");
        // A value set by hand (here 20 µs) is what comes back.
        std::fs::write(&setting, "20").unwrap();
        drop(NoHalt::request_at(&setting, &record, 7, below_1000).unwrap());
        assert_eq!(text(&setting), "20");
    }

    #[test]
    fn the_last_of_two_holders_restores() {
        let (setting, record) = place("two", "0");
        let a = NoHalt::request_at(&setting, &record, 7, below_1000).unwrap();
        let b = NoHalt::request_at(&setting, &record, 8, below_1000).unwrap();
        assert_eq!(
            text(&record),
            "original 0\nholder 7\nholder 8\n",
            "the value from before both"
        );
        drop(a);
        assert_eq!(text(&setting), "n/a", "8 still holds it");
        assert_eq!(text(&record), "original 0\nholder 8\n");
        drop(b);
        assert_eq!(text(&setting), "0");
    }

    #[test]
    fn a_holder_that_died_is_dropped_and_its_value_restored_by_the_next() {
        let (setting, record) = place("dead", "n/a");
        // What a server killed with SIGKILL leaves: the core polling, and the record.
        std::fs::write(&record, "original 0\nholder 4242\n").unwrap();
        let held = NoHalt::request_at(&setting, &record, 7, below_1000).unwrap();
        assert_eq!(
            text(&record),
            "original 0\nholder 7\n",
            "not n/a: the value from before 4242"
        );
        drop(held);
        assert_eq!(text(&setting), "0");
    }

    #[test]
    fn a_holder_whose_partner_died_restores_on_its_own_release() {
        let (setting, record) = place("partner", "0");
        let held = NoHalt::request_at(&setting, &record, 7, below_1000).unwrap();
        // Another server took it too, then was killed.
        let mut r = Record::parse(&text(&record));
        r.holders.push(4242);
        std::fs::write(&record, r.render()).unwrap();
        drop(held);
        assert_eq!(text(&setting), "0");
        assert_eq!(text(&record), "");
    }

    #[test]
    fn an_unwritable_setting_is_an_error_naming_it_and_records_nothing() {
        let (setting, record) = place("missing", "0");
        let gone = setting.with_file_name("no-such-dir/pm_qos_resume_latency_us");
        let e = NoHalt::request_at(&gone, &record, 7, below_1000).unwrap_err();
        assert!(e.to_string().contains("no-such-dir"), "{e}");
        assert_eq!(text(&record), "");
    }

    #[test]
    fn records_round_trip_and_ignore_what_they_do_not_know() {
        let r = Record {
            original: Some("n/a".into()),
            holders: vec![1, 22],
        };
        assert_eq!(Record::parse(&r.render()), r);
        assert_eq!(Record::parse("junk\nholder x\noriginal \nholder 5\n").holders, vec![5]);
        assert_eq!(Record::parse("").render(), "");
    }

    #[test]
    fn a_live_server_is_a_process_named_nanopush_and_not_a_zombie() {
        // This test binary is `nanopush_server-<hash>`: like the haptic bridge `nanopush-haptic`,
        // not a server, though live under its own name.
        let me = std::process::id();
        let my_name = std::fs::read_to_string("/proc/self/comm").unwrap();
        assert!(my_name.trim_end().starts_with("nanopush_"), "{my_name}");
        assert!(!is_live_server(me));
        assert!(is_live_named(me, my_name.trim_end()));
        let mut child = std::process::Command::new("sleep").arg("5").spawn().unwrap();
        // Named `sleep` once it has exec'd.
        let exec = (0..500).any(|_| {
            std::thread::sleep(std::time::Duration::from_millis(2));
            is_live_named(child.id(), "sleep")
        });
        assert!(exec, "the child runs as sleep");
        assert!(!is_live_server(child.id()));
        // Killed and not yet reaped: a zombie, not live.
        let _ = child.kill();
        let zombie = (0..500).any(|_| {
            std::thread::sleep(std::time::Duration::from_millis(2));
            !is_live_named(child.id(), "sleep")
        });
        assert!(zombie, "a killed child is a zombie until reaped");
        let _ = child.wait();
        assert!(!is_live_named(child.id(), "sleep"));
    }
}
