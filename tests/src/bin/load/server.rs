//! The server a level measures: a fresh `nanopush serve` on a free port, its stop, its log, and
//! plain HTTP GETs of its API.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};

use crate::{Opts, TOKEN};

/// A `nanopush serve` on a free port in a scratch directory; killed (if still running) and its
/// directory removed on drop.
pub struct Server {
    child: Child,
    pub addr: String,
    dir: PathBuf,
}

impl Server {
    pub fn start(o: &Opts, viewers: usize) -> Result<Server, String> {
        let dir = std::env::temp_dir().join(format!("nanopush-load-{}-{viewers}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
        let log = std::fs::File::create(dir.join("server.log")).map_err(|e| format!("creating the server log: {e}"))?;
        let mut child = Command::new(&o.server)
            .current_dir(nanopush_e2e::workspace())
            .args([
                "serve",
                "--port",
                "0",
                "--haptic",
                "none",
                "--max-clients",
                "2000",
                "--max-clients-per-address",
                "2000",
            ])
            .args([
                "--operator-token",
                TOKEN,
                "--rate-hz",
                &o.rate_hz.to_string(),
                "--data-dir",
            ])
            .arg(dir.join("records"))
            .args(o.allow_cpu_halt.then_some("--allow-cpu-halt"))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .map_err(|e| format!("starting {}: {e}", o.server.display()))?;
        let addr = match nanopush_e2e::listening_addr(&mut child) {
            Ok(addr) => addr.trim().to_string(),
            Err(first) => {
                let _ = child.kill();
                let _ = child.wait();
                let log = std::fs::read_to_string(dir.join("server.log")).unwrap_or_default();
                return Err(format!(
                    "the server did not start (first line {first:?}); its log:\n{log}"
                ));
            }
        };
        Ok(Server { child, addr, dir })
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// SIGTERM, then wait (30 s at most, then SIGKILL): the time to exit and the exit code.
    pub async fn stop(&mut self) -> (f64, Option<i32>, bool) {
        let t = Instant::now();
        // SAFETY: kill(2) on our own child's pid, which has not been waited for (so not reused).
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
        }
        loop {
            match self.child.try_wait() {
                Ok(Some(status)) => return (t.elapsed().as_secs_f64(), status.code(), false),
                Ok(None) if t.elapsed() < Duration::from_secs(30) => {
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
                _ => {
                    let _ = self.child.kill();
                    let code = self.child.wait().ok().and_then(|s| s.code());
                    return (t.elapsed().as_secs_f64(), code, true);
                }
            }
        }
    }

    /// The server log's WARN and ERROR lines (distinct messages, first few), and how many.
    pub fn log_problems(&self) -> (usize, Vec<String>) {
        let log = std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default();
        let bad: Vec<&str> = log
            .lines()
            .filter(|l| l.contains(" WARN ") || l.contains(" ERROR "))
            .collect();
        let mut distinct = BTreeSet::new();
        for l in &bad {
            // Drop the timestamp so repeated messages collapse.
            let msg = l.split_once(' ').map_or(*l, |(_, rest)| rest).trim();
            distinct.insert(msg.to_string());
        }
        (bad.len(), distinct.into_iter().take(5).collect())
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A plain HTTP/1.1 GET: the body of a 200 answer.
pub async fn http_get(addr: &str, path: &str) -> Result<String, String> {
    let fetch = async {
        let mut s = tokio::net::TcpStream::connect(addr).await?;
        s.write_all(nanopush_e2e::client::request(addr, path).as_bytes())
            .await?;
        let mut buf = Vec::new();
        s.read_to_end(&mut buf).await?;
        Ok::<_, std::io::Error>(buf)
    };
    let buf = tokio::time::timeout(Duration::from_secs(10), fetch)
        .await
        .map_err(|_| format!("GET {path}: no answer in 10 s"))?
        .map_err(|e| format!("GET {path}: {e}"))?;
    let (status, body) = nanopush_e2e::client::parse_response(&buf).map_err(|e| format!("GET {path}: {e}"))?;
    if status != 200 {
        return Err(format!("GET {path}: HTTP {status}"));
    }
    String::from_utf8(body).map_err(|e| format!("GET {path}: {e}"))
}
