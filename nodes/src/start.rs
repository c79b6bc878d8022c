//! How a parameter-only node starts: the ROS 2 command line, logging, the shutdown flag, the node,
//! and a warning for each parameter the node does not know.

use dynlab_ros::{ArgsError, Node, NodeArgs, NodeError, Shutdown, ShutdownError};

/// Why a node could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// Arguments outside `--ros-args`: parameter-only nodes take none.
    #[error(
        "{node} takes no arguments outside --ros-args (got `{extra}`); set parameters with \
         --ros-args -p name:=value or --params-file FILE"
    )]
    ExtraArgument {
        /// The node's default name.
        node: String,
        /// The first unexpected argument.
        extra: String,
    },
    /// A malformed ROS 2 command line.
    #[error(transparent)]
    Args(#[from] ArgsError),
    /// The SIGINT/SIGTERM handler could not be installed.
    #[error(transparent)]
    Shutdown(#[from] ShutdownError),
    /// The DDS participant or node could not be created.
    #[error(transparent)]
    Node(#[from] NodeError),
}

/// A started node with its shutdown flag.
pub struct Started {
    /// The node (parameters, publishers, subscriptions, clock).
    pub node: Node,
    /// Set by SIGINT/SIGTERM.
    pub shutdown: Shutdown,
}

/// Starts the node `name` from this process's command line: no arguments outside `--ros-args`,
/// logging at the requested level, SIGINT/SIGTERM as a shutdown flag, and a warning for every
/// parameter not in `known` (a typo would otherwise be silently ignored).
pub fn start_node(name: &str, known: &[&str]) -> Result<Started, StartError> {
    let args = NodeArgs::from_env()?;
    if let Some(extra) = args.program_args.first() {
        return Err(StartError::ExtraArgument {
            node: name.to_owned(),
            extra: extra.clone(),
        });
    }
    dynlab_ros::init_logging(args.log_level);
    let shutdown = Shutdown::install()?;
    let node = Node::new(name, &args)?;
    for key in node.params().unknown_keys(known) {
        tracing::warn!(
            "unknown parameter `{key}` ignored (known: {})",
            known.join(", ")
        );
    }
    Ok(Started { node, shutdown })
}
