//! `mvem serve`: the web explorer (a JSON API and a single-page app, see `mvem_serve`) on a
//! local port; `--load-test` measures it under concurrent load instead.

use crate::common::{self, usage};
use anyhow::{Context, Result};
use mvem::params::Params;
use mvem_serve::client;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;

/// Arguments of `mvem serve`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem serve                         # then open http://127.0.0.1:8080
  mvem serve --port 9000 --open
  mvem serve --params my_params.toml --params tuned.json
  mvem serve --load-test             # 400 requests from 32 client threads: p50/p99, errors

The page and the API (docs/serve.md) choose the model order (8/10/12) and among the parameter
sets named here (\"published\" is always there; a file is named by its file stem). The API reads
no file after start. It binds 127.0.0.1 unless --host says otherwise. Ctrl-C stops it.")]
pub struct Args {
    /// Address to bind; anything but a loopback address exposes the server to the network.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: IpAddr,
    /// Port (0: any free port).
    #[arg(long, default_value = "8080")]
    pub port: u16,
    /// Open the page in the default browser once the server listens.
    #[arg(long)]
    pub open: bool,
    /// Parameter file (TOML, nested JSON or the authors' flat JSON) offered besides the
    /// published set; repeatable.
    #[arg(long, value_name = "FILE")]
    pub params: Vec<PathBuf>,
    /// Computations at once [default: 2 x cores].
    #[arg(long, value_name = "N")]
    pub workers: Option<usize>,
    /// Instead of serving: start on a free loopback port, send --requests steady-state requests
    /// from --clients threads at once, print the latency quantiles and check the server stays
    /// healthy (exit 1 on a 5xx answer or a dropped connection).
    #[arg(long)]
    pub load_test: bool,
    /// Requests of --load-test.
    #[arg(long, default_value = "400", value_name = "N")]
    pub requests: usize,
    /// Client threads of --load-test.
    #[arg(long, default_value = "32", value_name = "N")]
    pub clients: usize,
}

/// Run `mvem serve`.
pub fn run(a: &Args) -> Result<()> {
    let mut config = mvem_serve::Config::local(a.port);
    config.addr = SocketAddr::new(a.host, a.port);
    config.cycles = vec![("whtc".to_string(), common::WHTC_CSV)];
    if let Some(w) = a.workers {
        if w == 0 {
            return Err(usage("--workers 0: at least 1"));
        }
        config.limits.workers = w;
    }
    for p in &a.params {
        let name = p
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| p.display().to_string());
        if config.params.iter().any(|(n, _)| *n == name) {
            return Err(usage(format!(
                "--params {}: a parameter set named {name:?} is already given",
                p.display()
            )));
        }
        let params: Params = mvem::io::params::load_params(p)
            .with_context(|| format!("cannot use parameter file {}", p.display()))?;
        config.params.push((name, params));
    }
    if a.load_test {
        return load_test(config, a.requests, a.clients);
    }
    if !a.host.is_loopback() {
        eprintln!(
            "warning: binding {}: the server is reachable from the network (it has no authentication)",
            a.host
        );
    }
    let open = a.open;
    mvem_serve::run(config, |addr| {
        let url = format!("http://{addr}");
        println!("listening on {url}");
        if open {
            open_browser(&url);
        }
    })
    .map_err(|e| match e {
        mvem_serve::ServeError::Bind { .. } | mvem_serve::ServeError::Config(_) => {
            usage(e.to_string())
        }
        other => anyhow::Error::new(other),
    })
}

fn open_browser(url: &str) {
    let cmd = if cfg!(target_os = "macos") {
        "open"
    } else if cfg!(windows) {
        "explorer"
    } else {
        "xdg-open"
    };
    if let Err(e) = std::process::Command::new(cmd).arg(url).spawn() {
        eprintln!("warning: cannot open a browser ({cmd}: {e}); open {url} yourself");
    }
}

/// Targets of the load test: steady states at a few points of the 8/10/12-state models.
fn load_targets() -> Vec<String> {
    let mut t = Vec::new();
    for (n_e, u_delta, u_egr, u_vgt) in [
        (1500.0, 110.0, 80.0, 75.0),
        (1200.0, 50.0, 0.0, 25.0),
        (1800.0, 150.0, 40.0, 60.0),
        (1000.0, 80.0, 60.0, 45.0),
    ] {
        for model in [8, 10, 12] {
            t.push(format!(
                "/api/steady?n_e={n_e}&u_delta={u_delta}&u_egr={u_egr}&u_vgt={u_vgt}&model={model}"
            ));
        }
    }
    t
}

fn load_test(mut config: mvem_serve::Config, requests: usize, clients: usize) -> Result<()> {
    if requests == 0 || clients == 0 {
        return Err(usage("--requests and --clients: at least 1"));
    }
    config.addr = SocketAddr::from(([127, 0, 0, 1], 0));
    let server = mvem_serve::start(config).context("cannot start the server")?;
    let addr = server.addr;
    let targets = load_targets();
    // one warm-up request per target (page faults, lazy initialization), not counted
    for t in &targets {
        client::get(addr, t).with_context(|| format!("warm-up {t}"))?;
    }
    let r = client::load(addr, &targets, requests, clients);
    let health = client::get(addr, "/api/health");
    println!(
        "{} steady-state requests from {} client threads on {addr} ({} targets, 8/10/12 states)",
        r.requests,
        clients,
        targets.len()
    );
    println!(
        "answers: {} ok, {} 4xx, {} 5xx, {} dropped; wall {} ({:.0} requests/s)",
        r.ok,
        r.client_errors,
        r.server_errors,
        r.dropped,
        common::fmt_duration(r.wall),
        r.requests as f64 / r.wall
    );
    println!(
        "latency: p50 {}, p90 {}, p99 {}, max {}",
        common::fmt_duration(r.quantile(0.5)),
        common::fmt_duration(r.quantile(0.9)),
        common::fmt_duration(r.quantile(0.99)),
        common::fmt_duration(r.quantile(1.0))
    );
    let healthy = matches!(&health, Ok(h) if h.status == 200);
    println!(
        "health afterwards: {}",
        if healthy { "ok" } else { "NOT ok" }
    );
    server.stop().context("server shutdown")?;
    if r.server_errors > 0 || r.dropped > 0 || r.ok + r.client_errors != r.requests || !healthy {
        anyhow::bail!("load test failed: 5xx answers, dropped connections or an unhealthy server");
    }
    Ok(())
}
