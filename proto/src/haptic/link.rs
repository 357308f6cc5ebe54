//! The haptic link's iceoryx2 set-up, shared by both processes: its configuration built in
//! code, its nodes and its two services.

use iceoryx2::prelude::ZeroCopySend;

use super::{FORCE_FEEDBACK_SERVICE, HAPTIC_STATE_SERVICE};
use super::{ForceFeedback, HapticState, MAX_NODES, MAX_PUBLISHERS, MAX_SUBSCRIBERS};

/// Environment variable naming the haptic link's namespace: processes with the same value (or
/// none) find each other; different values keep two links on one machine apart (two
/// instruments, or tests running side by side). Letters, digits, `-` and `_`, at most 32.
pub const NAMESPACE_ENV: &str = "NANOPUSH_HAPTIC_NAMESPACE";

/// The iceoryx2 configuration both processes use, built in code: iceoryx2's defaults (shared
/// memory under `/dev/shm`, node records under `/tmp/iceoryx2`, dead nodes cleaned up when a node
/// is created or dropped), with the file prefix `nanopush_` or `nanopush_<namespace>_` from
/// [`NAMESPACE_ENV`]. Passing it to `NodeBuilder::config` skips iceoryx2's config-file search and
/// its "No config file was loaded" warning.
pub fn ipc_config() -> iceoryx2::config::Config {
    ipc_config_in(&std::env::var(NAMESPACE_ENV).unwrap_or_default())
}

/// Whether `ns` is a valid namespace (empty: the default link).
pub fn valid_namespace(ns: &str) -> bool {
    ns.len() <= 32 && ns.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

/// [`ipc_config`] for the namespace `ns` (empty: the default; an invalid one is taken as the
/// default here, and refused by [`ipc_node`]).
pub fn ipc_config_in(ns: &str) -> iceoryx2::config::Config {
    use iceoryx2::prelude::SemanticString;
    let mut cfg = iceoryx2::config::Config::default();
    let prefix = if ns.is_empty() || !valid_namespace(ns) {
        "nanopush_".to_string()
    } else {
        format!("nanopush_{ns}_")
    };
    if let Ok(p) = iceoryx2::prelude::FileName::new(prefix.as_bytes()) {
        cfg.global.prefix = p;
    }
    cfg
}

/// Removes the resources of dead nodes on the link `ns` (processes killed with SIGKILL): what
/// a new node does when it is created, for a caller that has none (a test's clean-up).
pub fn cleanup_dead_nodes_in(ns: &str) {
    use iceoryx2::prelude::*;
    if let Ok(node) = NodeBuilder::new()
        .config(&ipc_config_in(ns))
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
    {
        let _ = node.try_cleanup_dead_nodes();
    }
}

/// An iceoryx2 node of the haptic link.
pub type IpcNode = iceoryx2::node::Node<iceoryx2::service::ipc::Service>;
/// A service of the haptic link carrying `T`.
pub type IpcService<T> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<iceoryx2::service::ipc::Service, T, ()>;

/// Why the haptic link could not be set up.
#[derive(Debug)]
pub struct LinkSetupError(pub String);

impl std::fmt::Display for LinkSetupError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for LinkSetupError {}

/// A node named `name` with the [`ipc_config`], that leaves the process's signals alone
/// (`SignalHandlingMode::Disabled`: the host decides what SIGINT and SIGTERM do). Creating a node
/// removes the resources of nodes whose processes died (iceoryx2's default
/// `cleanup_dead_nodes_on_creation`), so a bridge or server killed with SIGKILL leaves nothing
/// that blocks the next one.
pub fn ipc_node(name: &str) -> Result<IpcNode, LinkSetupError> {
    use iceoryx2::prelude::*;
    let ns = std::env::var(NAMESPACE_ENV).unwrap_or_default();
    if !valid_namespace(&ns) {
        return Err(LinkSetupError(format!(
            "{NAMESPACE_ENV}={ns:?} is not a valid link namespace; allowed: at most 32 letters, digits, '-' and '_'"
        )));
    }
    let node_name: NodeName = name
        .try_into()
        .map_err(|e| LinkSetupError(format!("node name {name:?}: {e:?}")))?;
    let node = NodeBuilder::new()
        .config(&ipc_config())
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| LinkSetupError(format!("iceoryx2 node {name}: {e:?}")))?;
    let _ = node.try_cleanup_dead_nodes();
    Ok(node)
}

fn service<T>(node: &IpcNode, name: &str) -> Result<IpcService<T>, LinkSetupError>
where
    T: std::fmt::Debug + ZeroCopySend + Copy + 'static,
{
    let service_name: iceoryx2::prelude::ServiceName = name
        .try_into()
        .map_err(|e| LinkSetupError(format!("service name {name:?}: {e:?}")))?;
    node.service_builder(&service_name)
        .publish_subscribe::<T>()
        .max_publishers(MAX_PUBLISHERS)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(|e| LinkSetupError(format!("iceoryx2 service {name}: {e:?}")))
}

/// The bridge → server service ([`HAPTIC_STATE_SERVICE`]), with the same attributes on both
/// sides.
pub fn state_service(node: &IpcNode) -> Result<IpcService<HapticState>, LinkSetupError> {
    service(node, HAPTIC_STATE_SERVICE)
}

/// The server → bridge service ([`FORCE_FEEDBACK_SERVICE`]).
pub fn force_service(node: &IpcNode) -> Result<IpcService<ForceFeedback>, LinkSetupError> {
    service(node, FORCE_FEEDBACK_SERVICE)
}

/// Whether a publisher creation failed because the service already has its one publisher (a
/// live bridge, or a live server).
pub fn is_publisher_taken(e: &iceoryx2::port::publisher::PublisherCreateError) -> bool {
    matches!(
        e,
        iceoryx2::port::publisher::PublisherCreateError::ExceedsMaxSupportedPublishers
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Namespaces: letters, digits, `-` and `_`, at most 32 (empty: the default link); the
    /// config's file prefix carries a valid one, and an invalid one falls back to the default.
    #[test]
    fn a_namespace_is_a_few_letters_digits_dashes_and_underscores() {
        for ok in ["", "lab1", "Lab-2_b", &"x".repeat(32)] {
            assert!(valid_namespace(ok), "{ok:?}");
        }
        for bad in [&"x".repeat(33) as &str, "a b", "a/b", "a.b", "ü", "lab\n"] {
            assert!(!valid_namespace(bad), "{bad:?}");
        }
        let prefix = |ns: &str| ipc_config_in(ns).global.prefix.to_string();
        assert_eq!(prefix(""), "nanopush_");
        assert_eq!(prefix("lab-2"), "nanopush_lab-2_");
        assert_eq!(prefix("a b"), "nanopush_");
    }

    /// The link's configuration is ours, not iceoryx2's default (whose files would be
    /// `iox2_*`), whatever namespace the environment names; a node of it can be made.
    #[test]
    fn the_link_uses_the_nanopush_prefix_and_makes_nodes() {
        assert!(ipc_config().global.prefix.to_string().starts_with("nanopush_"));
        let node = ipc_node("nanopush_proto_test").expect("a node of the link");
        assert_eq!(node.name().as_str(), "nanopush_proto_test");
    }

    /// The dead nodes of a link (a process killed with SIGKILL leaves its node behind) are
    /// removed by [`cleanup_dead_nodes_in`]. The test runs itself again as the process that
    /// dies.
    #[test]
    fn a_killed_processs_node_is_cleaned_up() {
        use iceoryx2::prelude::*;
        if std::env::var_os("NANOPUSH_PROTO_TEST_DIE").is_some() {
            let _node = ipc_node("nanopush_dying").expect("a node");
            // SAFETY: kills this (child) process, which is the point.
            unsafe {
                libc::kill(libc::getpid(), libc::SIGKILL);
            }
        }
        let ns = format!("prototest{}", std::process::id());
        let status = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "haptic::link::tests::a_killed_processs_node_is_cleaned_up",
                "--nocapture",
            ])
            .env("NANOPUSH_PROTO_TEST_DIE", "1")
            .env(NAMESPACE_ENV, &ns)
            .status()
            .unwrap();
        assert!(!status.success(), "the child was to be killed");
        let dead = || {
            let mut n = 0;
            iceoryx2::node::Node::<ipc::Service>::list(&ipc_config_in(&ns), |state| {
                if matches!(state, iceoryx2::node::NodeState::Dead(_)) {
                    n += 1;
                }
                CallbackProgression::Continue
            })
            .unwrap();
            n
        };
        assert_eq!(dead(), 1);
        cleanup_dead_nodes_in(&ns);
        assert_eq!(dead(), 0);
        // What iceoryx2 keeps of a prefix once it has been used (its 16-byte management segment).
        let mine = format!("nanopush_{ns}_");
        for dir in ["/dev/shm", "/tmp/iceoryx2/nodes", "/tmp/iceoryx2/services"] {
            for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
                if e.file_name().to_string_lossy().starts_with(&mine) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
    }

    #[test]
    fn a_taken_publisher_is_told_from_other_failures() {
        use iceoryx2::port::publisher::PublisherCreateError as E;
        assert!(is_publisher_taken(&E::ExceedsMaxSupportedPublishers));
        assert!(!is_publisher_taken(&E::UnableToCreateDataSegment));
        assert_eq!(LinkSetupError("no shm".into()).to_string(), "no shm");
    }
}
