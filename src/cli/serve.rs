//! CLI of `errmap serve`: the monitor web server, and `errmap serve user add|remove|list` for its users file.

use super::exit::Result;
use super::Globals;
use errmap::serve::users::{Role, Users};
use errmap::serve::{self, Config};
use errmap::Error;
use std::io::Read;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct ServeArgs {
    #[command(subcommand)]
    pub command: Option<ServeCommand>,
    #[command(flatten)]
    pub server: ServerArgs,
}

#[derive(Debug, clap::Args)]
pub struct ServerArgs {
    /// The temperature-history store (as the thermal commands and `errmap live` name it).
    #[arg(long, value_name = "STORE.sqlite")]
    pub db: Option<PathBuf>,
    /// The folder of batch runs to show (read-only), e.g. out/.
    #[arg(long, value_name = "DIR")]
    pub runs: Option<PathBuf>,
    /// The state file a running `errmap live --state` rewrites.
    #[arg(long, value_name = "STATE.json")]
    pub live: Option<PathBuf>,
    /// Address and port to listen on (port 0: a free port, printed at start).
    #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:8443")]
    pub bind: SocketAddr,
    /// TLS certificate chain, PEM (with --tls-key).
    #[arg(long, value_name = "PEM", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// TLS private key, PEM (with --tls-cert).
    #[arg(long, value_name = "PEM", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// The users file; default users.toml beside the store.
    #[arg(long, value_name = "FILE")]
    pub users: Option<PathBuf>,
    /// A reverse proxy whose X-Forwarded-For is believed (repeat for several).
    #[arg(long, value_name = "ADDR")]
    pub trusted_proxy: Vec<IpAddr>,
    /// Serve plain HTTP on a non-loopback address (passwords cross the network unencrypted).
    #[arg(long)]
    pub insecure_http: bool,
    /// A session unused this long ends.
    #[arg(long, value_name = "SECONDS", default_value_t = 1800)]
    pub idle_timeout: u64,
    /// A session ends this long after its login.
    #[arg(long, value_name = "SECONDS", default_value_t = 8 * 3600)]
    pub session_lifetime: u64,
    /// Most live-page streams at once.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub max_live_clients: usize,
}

#[derive(Debug, clap::Subcommand)]
pub enum ServeCommand {
    /// Users of the monitor.
    #[command(subcommand)]
    User(UserCommand),
}

#[derive(Debug, clap::Subcommand)]
pub enum UserCommand {
    /// Add a user (or, with --replace, give one a new password or role); the password is read from stdin.
    Add {
        name: String,
        #[arg(long, value_enum)]
        role: RoleArg,
        #[arg(long, value_name = "FILE")]
        users: PathBuf,
        /// Read the password from standard input (the only way: never from the command line).
        #[arg(long, required = true)]
        password_stdin: bool,
        /// Replace the user if it exists.
        #[arg(long)]
        replace: bool,
    },
    /// Remove a user (their sessions end within a second on a running server).
    Remove {
        name: String,
        #[arg(long, value_name = "FILE")]
        users: PathBuf,
    },
    /// List the users and their roles.
    List {
        #[arg(long, value_name = "FILE")]
        users: PathBuf,
    },
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum RoleArg {
    Viewer,
    Operator,
}

fn read_password() -> Result<String> {
    let mut text = String::new();
    std::io::stdin()
        .take(64 * 1024)
        .read_to_string(&mut text)
        .map_err(|e| Error::read("<stdin>", e))?;
    // One line: the password without its line end.
    let line = text.lines().next().unwrap_or("").to_string();
    Ok(line)
}

pub fn run(args: ServeArgs, _globals: Globals) -> Result<i32> {
    match args.command {
        Some(ServeCommand::User(cmd)) => run_user(cmd),
        None => run_server(args.server),
    }
}

fn run_user(cmd: UserCommand) -> Result<i32> {
    match cmd {
        UserCommand::Add {
            name,
            role,
            users,
            password_stdin: _,
            replace,
        } => {
            let password = read_password()?;
            let mut list = Users::load(&users, true)?;
            let role = match role {
                RoleArg::Viewer => Role::Viewer,
                RoleArg::Operator => Role::Operator,
            };
            list.add(&name, role, &password, replace)?;
            list.save(&users)?;
            info!("wrote {} ({} users)", users.display(), list.users.len());
        }
        UserCommand::Remove { name, users } => {
            let mut list = Users::load(&users, false)?;
            list.remove(&name)?;
            list.save(&users)?;
            info!("wrote {} ({} users)", users.display(), list.users.len());
        }
        UserCommand::List { users } => {
            for u in Users::load(&users, false)?.users {
                outln!("{}\t{}", u.name, u.role.as_str());
            }
        }
    }
    Ok(0)
}

fn run_server(a: ServerArgs) -> Result<i32> {
    let db = a.db.ok_or_else(|| {
        Error::usage(
            "errmap serve needs the store",
            "give --db STORE.sqlite (the store of the thermal commands or of errmap live)",
        )
    })?;
    if a.idle_timeout == 0 || a.session_lifetime == 0 {
        return Err(Error::usage(
            "--idle-timeout and --session-lifetime must be at least 1 s",
            "e.g. --idle-timeout 1800 --session-lifetime 28800",
        )
        .into());
    }
    let users = a.users.unwrap_or_else(|| serve::default_users_path(&db));
    let cfg = Config {
        db,
        runs: a.runs,
        live: a.live,
        bind: a.bind,
        tls: a.tls_cert.zip(a.tls_key),
        users,
        trusted_proxies: a.trusted_proxy,
        insecure_http: a.insecure_http,
        idle_timeout: Duration::from_secs(a.idle_timeout),
        absolute_timeout: Duration::from_secs(a.session_lifetime),
        max_live_clients: a.max_live_clients.max(1),
    };
    serve::run(cfg, |url| {
        // The one line on stdout: scripts and tests read the address from it.
        println!("errmap serve: listening on {url}");
        use std::io::Write;
        let _ = std::io::stdout().flush();
    })?;
    Ok(0)
}
