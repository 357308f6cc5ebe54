//! `nanopush token add|list|revoke`: the token file of named operators and viewers. `add`
//! prints the new token once (the file keeps only its argon2 hash); `revoke` removes it, and a
//! running server closes that person's sessions within about 1.5 s. Both change the file under
//! an exclusive lock (`FILE.lock`), so runs at once lose nobody's change.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use nanopush_server::auth::tokens::{TokenTable, parse_role, role_name};

/// Arguments of `nanopush token`.
#[derive(Args, Debug)]
pub struct TokenArgs {
    /// The token file (the one given to `nanopush serve --token-file`).
    #[arg(long, default_value = "tokens", global = true)]
    token_file: PathBuf,
    #[command(subcommand)]
    action: TokenAction,
}

/// What to do with the token file.
#[derive(Subcommand, Debug)]
enum TokenAction {
    /// Give NAME a new token with a role; prints it once (keep it: only its hash is stored).
    Add {
        /// The person's name: 1 to 64 letters, digits, '.', '_', '-' or '@'.
        name: String,
        /// `operator` (may take the lease and command) or `viewer` (watches).
        #[arg(long, value_parser = ["operator", "viewer"])]
        role: String,
    },
    /// The people with a token, and their roles (never the tokens).
    List,
    /// Remove NAME's token: a server using the file closes their sessions within about 1.5 s.
    Revoke {
        /// The person's name.
        name: String,
    },
}

/// Runs `nanopush token`.
pub fn run(a: &TokenArgs) -> anyhow::Result<String> {
    let path = &a.token_file;
    match &a.action {
        TokenAction::Add { name, role } => {
            let role = parse_role(role).context("--role: allowed: operator, viewer")?;
            let token = TokenTable::update(path, true, |t| t.add(name, role))?;
            Ok(format!(
                "added {name} ({}) to {}\ntoken (shown once; give it to {name}, who opens the page with ?token=…):\n{token}\n",
                role_name(role),
                path.display()
            ))
        }
        TokenAction::List => {
            let table = TokenTable::read(path, false)?;
            let mut s = format!("{:<24} {:<9} id\n", "name", "role");
            for e in &table.entries {
                s.push_str(&format!("{:<24} {:<9} {}\n", e.name, role_name(e.role), e.id));
            }
            Ok(s)
        }
        TokenAction::Revoke { name } => {
            let gone = TokenTable::update(path, false, |t| t.revoke(name))?;
            Ok(format!(
                "revoked {name}'s token ({}, id {}) in {}\n",
                role_name(gone.role),
                gone.id,
                path.display()
            ))
        }
    }
}
