//! One cell of the haptic grid with the real processes: `nanopush serve --haptic external` and
//! `nanopush-haptic --device sim --operator OP --trace`, a `haptic` `scale` and `engage` from the
//! lease holder as the browser sends them, the script played to its end, and the trace judged by
//! [`nanopush_haptic::grid::judge`] (raw port energy, chatter, the hand force's limit, the tip
//! force's swing held in contact). The end-to-end test runs a subset (`tests/e2e/haptic_grid.rs`),
//! the `nanopush-haptic-grid` benchmark every cell.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use nanopush_haptic::bridge::CycleRow;
use nanopush_haptic::grid::{CellVerdict, judge};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use crate::{Proc, bin, client, listening_addr, workspace};

/// The operator token the cell's server is started with.
const TOKEN: &str = "haptic-grid-operator-token";
/// The simulated device's force limit (N).
pub const SIM_MAX_FORCE: f64 = 2.5;

/// What a cell gave.
#[derive(Debug, Clone)]
pub struct CellRun {
    /// The trace's measures.
    pub verdict: CellVerdict,
    /// The `scales` of the `ok` to the `scale` command.
    pub scales: Value,
    /// `/api/status`'s `haptic` at the end of the script.
    pub status: Value,
    /// Rows in the trace.
    pub rows: usize,
}

/// A cell's directory and link namespace; the processes' shared memory is removed on drop.
pub struct CellBench {
    /// Directory (scene, logs, trace, records).
    pub dir: PathBuf,
    /// The link's namespace.
    pub namespace: String,
    /// Keep the directory (a cell that failed, to read its trace and logs).
    pub keep: bool,
}

impl CellBench {
    /// A fresh directory under the system's temporary one, tagged `tag`, with the paper's scene
    /// starting the tip 2.2 µm above bare substrate away from its particle.
    pub fn new(tag: &str) -> CellBench {
        let dir = std::env::temp_dir().join(format!("nanopush-grid-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a temporary directory");
        let text = std::fs::read_to_string(workspace().join("scenes/paper-default.toml")).expect("the paper scene");
        let extra = "[scan]\ncentre_x_um = 20.0\ncentre_y_um = 20.0\nsize_um = 10.0\n";
        std::fs::write(
            dir.join("scene.toml"),
            format!(
                "{}\n{extra}",
                crate::with_strategy(&text, &[("start_height_um", "2.2")])
            ),
        )
        .expect("writing the scene");
        CellBench {
            dir,
            namespace: format!("grid{tag}{}", std::process::id()),
            keep: false,
        }
    }
}

impl Drop for CellBench {
    fn drop(&mut self) {
        nanopush_proto::haptic::cleanup_dead_nodes_in(&self.namespace);
        let prefix = format!("nanopush_{}_", self.namespace);
        if let Ok(dir) = std::fs::read_dir("/dev/shm") {
            for e in dir.flatten() {
                if e.file_name().to_string_lossy().starts_with(&prefix) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        if !self.keep && std::env::var_os("NANOPUSH_E2E_KEEP").is_none() && !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Runs `operator` at `nm_per_mm` and `pull_off_n` in `b`: the cell's measures, or why it could
/// not run (a process that did not start, a reply that did not come).
pub fn run_cell(b: &CellBench, operator: &str, nm_per_mm: f64, pull_off_n: f64) -> Result<CellRun, String> {
    let log = |name: &str| std::fs::File::create(b.dir.join(name)).map_err(|e| e.to_string());
    let mut server = Command::new(bin("nanopush"));
    server
        .current_dir(workspace())
        .env("NANOPUSH_HAPTIC_NAMESPACE", &b.namespace)
        .args([
            "serve",
            "--port",
            "0",
            "--haptic",
            "external",
            "--haptic-timeout-ms",
            "100",
        ])
        .args(["--operator-token", TOKEN, "--scene"])
        .arg(b.dir.join("scene.toml"))
        .arg("--data-dir")
        .arg(b.dir.join("records"))
        .stdout(Stdio::piped())
        .stderr(log("server.log")?);
    let mut srv = Proc(server.spawn().map_err(|e| format!("starting nanopush serve: {e}"))?);
    let addr = listening_addr(&mut srv.0).map_err(|l| format!("nanopush serve said {l:?}"))?;
    let trace = b.dir.join("trace.csv");
    let mut bridge = Proc(
        Command::new(bin("nanopush-haptic"))
            .current_dir(workspace())
            .env("NANOPUSH_HAPTIC_NAMESPACE", &b.namespace)
            .args(["--device", "sim", "--operator", operator, "--duration", "60"])
            .args(["--server-timeout-ms", "100", "--trace"])
            .arg(&trace)
            .stdout(Stdio::null())
            .stderr(log("bridge.log")?)
            .spawn()
            .map_err(|e| format!("starting nanopush-haptic: {e}"))?,
    );
    wait_status(&addr, 10.0, |s| s["haptic"]["link"] == "up")?;
    // The lease holder stays connected, reading (so that it answers the server's pings), until
    // the cell ends: z-control ends when the lease is freed.
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    let (mut holder, scales) = rt.block_on(scale_and_engage(&addr, nm_per_mm, pull_off_n))?;
    rt.spawn(async move { while let Some(Ok(_)) = holder.next().await {} });
    // The script ends by itself (the bridge exits 0 when it does).
    let deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        match bridge.0.try_wait() {
            Ok(Some(st)) if st.success() => break st,
            Ok(Some(st)) => return Err(format!("nanopush-haptic exited with {st}")),
            _ if Instant::now() > deadline => return Err("the script did not end within 60 s".into()),
            _ => std::thread::sleep(Duration::from_millis(50)),
        }
    };
    let _ = status;
    let status = get_status(&addr)?["haptic"].clone();
    drop(rt);
    drop(srv);
    let rows = read_trace(&trace)?;
    Ok(CellRun {
        verdict: judge(&rows, SIM_MAX_FORCE),
        scales,
        status,
        rows: rows.len(),
    })
}

/// The lease holder's socket.
type Socket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// As the lease holder: the scales, then `engage`; its socket (to keep open) and the `scales` of
/// the scale's `ok`.
async fn scale_and_engage(addr: &str, nm_per_mm: f64, pull_off_n: f64) -> Result<(Socket, Value), String> {
    let url = client::ws_url(addr, Some(TOKEN));
    let (mut ws, _) = tokio_tungstenite::connect_async(url.into_client_request().map_err(|e| e.to_string())?)
        .await
        .map_err(|e| format!("the WebSocket: {e}"))?;
    let mut ask = async |v: Value| -> Result<Value, String> {
        let id = v["id"].clone();
        ws.send(Message::Text(v.to_string().into()))
            .await
            .map_err(|e| e.to_string())?;
        let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
        loop {
            let m = tokio::time::timeout_at(deadline, ws.next())
                .await
                .map_err(|_| format!("no reply to {v}"))?
                .ok_or("the socket closed")?
                .map_err(|e| e.to_string())?;
            if let Message::Text(t) = m
                && let Ok(r) = serde_json::from_str::<Value>(t.as_str())
                && r["id"] == id
            {
                return if r["type"] == "ok" {
                    Ok(r)
                } else {
                    Err(format!("{v} refused: {r}"))
                };
            }
        }
    };
    ask(json!({"type": "take_lease", "id": 1})).await?;
    let ok = ask(
        json!({"type": "haptic", "id": 2, "action": "scale", "nm_per_mm": nm_per_mm,
        "pull_off_at_hand_n": pull_off_n}),
    )
    .await?;
    ask(json!({"type": "haptic", "id": 3, "action": "engage"})).await?;
    Ok((ws, ok["scales"].clone()))
}

fn get_status(addr: &str) -> Result<Value, String> {
    let (code, body) = client::get(addr, "/api/status").map_err(|e| e.to_string())?;
    if code != 200 {
        return Err(format!("/api/status answered {code}"));
    }
    serde_json::from_slice(&body).map_err(|e| e.to_string())
}

fn wait_status(addr: &str, secs: f64, pred: impl Fn(&Value) -> bool) -> Result<Value, String> {
    let deadline = Instant::now() + Duration::from_secs_f64(secs);
    loop {
        let s = get_status(addr)?;
        if pred(&s) {
            return Ok(s);
        }
        if Instant::now() > deadline {
            return Err(format!(
                "the haptic link did not come up within {secs} s: {}",
                s["haptic"]
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The bridge's trace (`--trace`) as cycle rows.
pub fn read_trace(path: &Path) -> Result<Vec<CycleRow>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default();
    if !header.ends_with("raw_port_energy_j,holding") {
        return Err(format!("an unexpected trace header {header:?}"));
    }
    lines
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            let f = |i: usize| -> Result<f64, String> {
                c.get(i)
                    .and_then(|v| v.parse::<f64>().ok())
                    .ok_or_else(|| format!("a bad trace row {l:?}"))
            };
            Ok(CycleRow {
                t: f(0)?,
                handle: f(1)?,
                force: f(2)?,
                tip_z: f(3)?,
                tip_force: f(4)?,
                link: c.get(5) == Some(&"up"),
                pc_damping: f(6)?,
                port_energy: f(7)?,
                raw_port_energy: f(8)?,
                holding: c.get(9) == Some(&"1"),
                latency_ns: 0,
            })
        })
        .collect()
}
