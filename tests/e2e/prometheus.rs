//! Lab monitoring end to end: a real Prometheus server (Debian's `prometheus`, installed by
//! `.ci/setup`) with the shipped alert rules scrapes a real `nanopush serve`, and a series and
//! the rules are read back through Prometheus' HTTP API.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nanopush_e2e::workspace;
use serde_json::Value;

use crate::util::{free_port, http_get, spawn_serve, tmp};

/// A process stopped on drop, its log shown after it stopped if the test failed.
struct Proc(Child, PathBuf);

impl Drop for Proc {
    fn drop(&mut self) {
        nanopush_e2e::stop(&mut self.0);
        if std::thread::panicking() {
            eprintln!("--- log ---\n{}", std::fs::read_to_string(&self.1).unwrap_or_default());
        }
    }
}

/// docs/server.md, "Lab monitoring: Prometheus (`deploy/prometheus/`)": the shipped `prometheus.yml` "scrapes `127.0.0.1:8080` every 5 s"
/// (`nanopush serve`'s default address and port) and loads `alerts.yml`. `promtool check
/// config` checks its syntax only.
#[test]
fn the_shipped_prometheus_config_scrapes_the_default_server_with_alerts() {
    let text = std::fs::read_to_string(workspace().join("deploy/prometheus/prometheus.yml")).unwrap();
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.starts_with('#') && !l.is_empty())
        .collect();
    for want in [
        "scrape_interval: 5s",
        "- alerts.yml",
        "- job_name: nanopush",
        "metrics_path: /metrics",
        "- targets: [\"127.0.0.1:8080\"]",
    ] {
        assert!(lines.contains(&want), "prometheus.yml has no line {want:?}");
    }
    assert_eq!(lines.iter().filter(|l| l.starts_with("- targets:")).count(), 1);
}

#[test]
fn prometheus_scrapes_the_server_and_loads_the_alert_rules() {
    let dir = tmp("prometheus");
    let server_log = dir.join("server.log");
    let (server, addr) = spawn_serve(&server_log, |c| {
        c.args(["--haptic", "none", "--data-dir"]).arg(dir.join("records"));
    });
    let _server = Proc(server, server_log);
    let alerts = workspace().join("deploy/prometheus/alerts.yml");
    let config = dir.join("prometheus.yml");
    std::fs::write(
        &config,
        format!(
            "global:\n  scrape_interval: 1s\n  evaluation_interval: 1s\nrule_files:\n  - {}\nscrape_configs:\n  - job_name: nanopush\n    static_configs:\n      - targets: [\"{addr}\"]\n",
            alerts.display()
        ),
    )
    .unwrap();
    let web = format!("127.0.0.1:{}", free_port());
    let prom_log = dir.join("prometheus.log");
    let _prometheus = Proc(
        Command::new("prometheus")
            .arg(format!("--config.file={}", config.display()))
            .arg(format!("--storage.tsdb.path={}", dir.join("data").display()))
            .arg(format!("--web.listen-address={web}"))
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&prom_log).unwrap())
            .spawn()
            .expect("starting prometheus (Debian package `prometheus`, installed by .ci/setup)"),
        prom_log,
    );
    // A series from the server, through Prometheus' query API.
    let deadline = Instant::now() + Duration::from_secs(60);
    let ticks = loop {
        // Nothing answers until Prometheus is up.
        if let Ok((200, body)) = nanopush_e2e::client::get(
            &web,
            "/api/v1/query?query=nanopush_loop_ticks_total%7Bjob%3D%22nanopush%22%7D",
        ) {
            let v: Value = serde_json::from_slice(&body).unwrap();
            if let Some(x) = v["data"]["result"][0]["value"][1].as_str() {
                break x.parse::<f64>().unwrap();
            }
        }
        assert!(
            Instant::now() < deadline,
            "no nanopush series in Prometheus within 60 s"
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    assert!(ticks > 0.0, "{ticks}");
    let (_, up) = http_get(&web, "/api/v1/query?query=up%7Bjob%3D%22nanopush%22%7D");
    let up: Value = serde_json::from_slice(&up).unwrap();
    assert_eq!(up["data"]["result"][0]["value"][1], "1");
    // The shipped rules are loaded, and a healthy server fires none of them.
    let (_, rules) = http_get(&web, "/api/v1/rules");
    let rules: Value = serde_json::from_slice(&rules).unwrap();
    let names: Vec<&str> = rules["data"]["groups"][0]["rules"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|r| r["name"].as_str())
        .collect();
    for alert in [
        "NanopushDown",
        "NanopushLoopOverruns",
        "NanopushHapticLinkDownWhileEngaged",
        "NanopushRecordWritesFailing",
        "NanopushDiskNearlyFull",
    ] {
        assert!(names.contains(&alert), "{alert} in {names:?}");
    }
    let (_, firing) = http_get(&web, "/api/v1/alerts");
    let firing: Value = serde_json::from_slice(&firing).unwrap();
    assert!(
        firing["data"]["alerts"]
            .as_array()
            .unwrap()
            .iter()
            .all(|a| a["state"] != "firing"),
        "{firing}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
