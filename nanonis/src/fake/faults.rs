//! The faults the fake controller can be told to commit, each on the first `times` calls of one
//! command (`*` for every command): `KIND:COMMAND[:MS][*TIMES]`.
//!
//! - `slow:CMD:MS` — answer after MS milliseconds;
//! - `error:CMD` — answer with an error block alone (status 1 and a description);
//! - `drop:CMD` — close the connection instead of answering;
//! - `wrong-name:CMD` — answer under another command's name;
//! - `short:CMD` — announce a body longer than the one sent, then close;
//! - `logger-drop:MS` — close the logger stream MS milliseconds after it starts.

use std::fmt;

/// What goes wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// Answer late.
    Slow(u64),
    /// An error block alone.
    Error,
    /// Close without answering.
    Drop,
    /// Answer under another name.
    WrongName,
    /// A body shorter than announced, then close.
    Short,
    /// The logger stream closes after this many ms.
    LoggerDrop(u64),
}

/// One fault: what, on which command, how many more times.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fault {
    /// What goes wrong.
    pub kind: FaultKind,
    /// The command it hits (`*` for every one).
    pub command: String,
    /// How many more times (`u32::MAX`: always).
    pub times: u32,
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?} on {} ({} left)", self.kind, self.command, self.times)
    }
}

impl std::str::FromStr for Fault {
    type Err = String;

    fn from_str(s: &str) -> Result<Fault, String> {
        let usage =
            "KIND:COMMAND[:MS][*TIMES] with KIND one of slow, error, drop, wrong-name, short, or logger-drop:MS";
        // `*TIMES` is the last `*` when what follows it is a count, `always` or nothing, and
        // it does not stand where a command does (`error:*` is every command, once).
        let suffix = s.rsplit_once('*').filter(|(spec, n)| {
            !spec.ends_with(':') && (n.is_empty() || *n == "always" || n.chars().all(|c| c.is_ascii_digit()))
        });
        let (spec, times) = match suffix {
            Some((spec, "")) | Some((spec, "always")) => (spec, u32::MAX),
            Some((spec, n)) => (
                spec,
                n.parse()
                    .map_err(|_| format!("fault {s:?}: times {n:?} is not a count; {usage}"))?,
            ),
            None => (s, 1),
        };
        let parts: Vec<&str> = spec.split(':').collect();
        let ms = |v: &str| {
            v.parse::<u64>()
                .map_err(|_| format!("fault {s:?}: {v:?} is not milliseconds; {usage}"))
        };
        let (kind, command) = match parts.as_slice() {
            ["slow", cmd, t] => (FaultKind::Slow(ms(t)?), *cmd),
            ["error", cmd] => (FaultKind::Error, *cmd),
            ["drop", cmd] => (FaultKind::Drop, *cmd),
            ["wrong-name", cmd] => (FaultKind::WrongName, *cmd),
            ["short", cmd] => (FaultKind::Short, *cmd),
            ["logger-drop", t] => (FaultKind::LoggerDrop(ms(t)?), "TCP Logger stream"),
            _ => return Err(format!("fault {s:?}: {usage}")),
        };
        if command.is_empty() {
            return Err(format!("fault {s:?}: no command; {usage}"));
        }
        Ok(Fault {
            kind,
            command: command.into(),
            times,
        })
    }
}

/// Takes the fault that hits `command` now, if any (and counts it down).
pub fn take(faults: &mut [Fault], command: &str) -> Option<FaultKind> {
    let f = faults.iter_mut().find(|f| {
        f.times > 0 && !matches!(f.kind, FaultKind::LoggerDrop(_)) && (f.command == command || f.command == "*")
    })?;
    if f.times != u32::MAX {
        f.times -= 1;
    }
    Some(f.kind)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_with_their_counts_and_bad_ones_say_the_syntax() {
        let f: Fault = "slow:Scan.FrameDataGrab:300*2".parse().unwrap();
        assert_eq!(f.kind, FaultKind::Slow(300));
        assert_eq!(f.times, 2);
        let f: Fault = "drop:FolMe.XYPosSet*".parse().unwrap();
        assert_eq!(f.times, u32::MAX);
        let f: Fault = "error:*".parse().unwrap();
        assert_eq!((f.command.as_str(), f.times), ("*", 1));
        let f: Fault = "slow:*:700*".parse().unwrap();
        assert_eq!(
            (f.kind, f.command.as_str(), f.times),
            (FaultKind::Slow(700), "*", u32::MAX)
        );
        let f: Fault = "drop:**3".parse().unwrap();
        assert_eq!((f.command.as_str(), f.times), ("*", 3));
        let e = "melt:Scan.Action".parse::<Fault>().unwrap_err();
        assert!(e.contains("KIND:COMMAND"), "{e}");
        assert!("slow:X:fast".parse::<Fault>().is_err());
    }

    #[test]
    fn a_fault_hits_its_command_as_many_times_as_asked() {
        let mut fs = vec!["error:ZCtrl.Withdraw*2".parse::<Fault>().unwrap()];
        assert_eq!(take(&mut fs, "FolMe.Stop"), None);
        assert_eq!(take(&mut fs, "ZCtrl.Withdraw"), Some(FaultKind::Error));
        assert_eq!(take(&mut fs, "ZCtrl.Withdraw"), Some(FaultKind::Error));
        assert_eq!(take(&mut fs, "ZCtrl.Withdraw"), None);
    }
}
