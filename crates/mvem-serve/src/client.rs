//! A minimal blocking HTTP/1.1 client (one request per connection) and the loopback load test
//! of `mvem serve --load-test`, used by the tests too.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// An HTTP answer.
#[derive(Debug, Clone)]
pub struct Reply {
    /// Status code.
    pub status: u16,
    /// Header lines as (lower-case name, value).
    pub headers: Vec<(String, String)>,
    /// Body.
    pub body: Vec<u8>,
}

impl Reply {
    /// The body as JSON (`Null` if it is not JSON).
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or(serde_json::Value::Null)
    }

    /// A header by lower-case name.
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
}

/// Send one request (`Connection: close`) and read the whole answer.
pub fn request(
    addr: SocketAddr,
    method: &str,
    target: &str,
    body: Option<&[u8]>,
    timeout: Duration,
) -> std::io::Result<Reply> {
    let mut s = TcpStream::connect_timeout(&addr, timeout)?;
    s.set_read_timeout(Some(timeout))?;
    s.set_write_timeout(Some(timeout))?;
    s.set_nodelay(true)?;
    let mut head = format!("{method} {target} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n");
    if let Some(b) = body {
        head.push_str(&format!(
            "Content-Type: application/json\r\nContent-Length: {}\r\n",
            b.len()
        ));
    }
    head.push_str("\r\n");
    let mut msg = head.into_bytes();
    if let Some(b) = body {
        msg.extend_from_slice(b);
    }
    // the server may answer (413) and close before the whole body is written
    let write_err = s.write_all(&msg).err();
    let mut raw = Vec::new();
    match s.read_to_end(&mut raw) {
        Ok(_) => {}
        Err(e) if raw.is_empty() => return Err(write_err.unwrap_or(e)),
        Err(_) => {}
    }
    parse(&raw).ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("malformed or empty HTTP answer ({} bytes)", raw.len()),
        )
    })
}

fn parse(raw: &[u8]) -> Option<Reply> {
    let end = raw.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = std::str::from_utf8(&raw[..end]).ok()?;
    let mut lines = head.split("\r\n");
    let status: u16 = lines.next()?.split(' ').nth(1)?.parse().ok()?;
    let headers: Vec<(String, String)> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let rest = &raw[end + 4..];
    let chunked = headers
        .iter()
        .any(|(k, v)| k == "transfer-encoding" && v.contains("chunked"));
    let body = if chunked {
        dechunk(rest)?
    } else {
        rest.to_vec()
    };
    Some(Reply {
        status,
        headers,
        body,
    })
}

fn dechunk(mut b: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    loop {
        let eol = b.windows(2).position(|w| w == b"\r\n")?;
        let size_str = std::str::from_utf8(&b[..eol]).ok()?;
        let size = usize::from_str_radix(size_str.split(';').next()?.trim(), 16).ok()?;
        b = &b[eol + 2..];
        if size == 0 {
            return Some(out);
        }
        out.extend_from_slice(b.get(..size)?);
        b = b.get(size + 2..)?;
    }
}

/// `GET target`.
pub fn get(addr: SocketAddr, target: &str) -> std::io::Result<Reply> {
    request(addr, "GET", target, None, Duration::from_secs(60))
}

/// `POST target` with a JSON body.
pub fn post(addr: SocketAddr, target: &str, body: &[u8]) -> std::io::Result<Reply> {
    request(addr, "POST", target, Some(body), Duration::from_secs(120))
}

/// Result of a load test.
#[derive(Debug, Clone)]
pub struct LoadReport {
    /// Requests sent.
    pub requests: usize,
    /// Answers by status class: 2xx, 4xx, 5xx.
    pub ok: usize,
    /// 4xx answers.
    pub client_errors: usize,
    /// 5xx answers.
    pub server_errors: usize,
    /// Requests without an answer (connection refused, reset, time-out, malformed).
    pub dropped: usize,
    /// Latencies of the answered requests \[s\], sorted.
    pub latencies: Vec<f64>,
    /// Wall time of the whole test \[s\].
    pub wall: f64,
}

impl LoadReport {
    /// Latency quantile `q` in \[0, 1\] \[s\] (nearest rank; NaN without answers).
    pub fn quantile(&self, q: f64) -> f64 {
        if self.latencies.is_empty() {
            return f64::NAN;
        }
        let n = self.latencies.len();
        let k = ((q * n as f64).ceil() as usize).clamp(1, n) - 1;
        self.latencies[k]
    }
}

/// Send `requests` GET requests of `targets` (round robin) from `clients` threads at once, one
/// connection per request, and collect statuses and latencies.
pub fn load(addr: SocketAddr, targets: &[String], requests: usize, clients: usize) -> LoadReport {
    let next = AtomicUsize::new(0);
    let t0 = Instant::now();
    let per_thread: Vec<(Vec<f64>, [usize; 4])> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..clients.max(1))
            .map(|_| {
                s.spawn(|| {
                    let mut lat = Vec::new();
                    let mut counts = [0usize; 4];
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= requests {
                            break;
                        }
                        let target = &targets[i % targets.len()];
                        let t = Instant::now();
                        match request(addr, "GET", target, None, Duration::from_secs(60)) {
                            Ok(r) => {
                                lat.push(t.elapsed().as_secs_f64());
                                counts[match r.status {
                                    200..=299 => 0,
                                    400..=499 => 1,
                                    _ => 2,
                                }] += 1;
                            }
                            Err(_) => counts[3] += 1,
                        }
                    }
                    (lat, counts)
                })
            })
            .collect();
        hs.into_iter()
            .map(|h| h.join().unwrap_or_default())
            .collect()
    });
    let wall = t0.elapsed().as_secs_f64();
    let mut latencies = Vec::new();
    let mut c = [0usize; 4];
    for (l, k) in per_thread {
        latencies.extend(l);
        for j in 0..4 {
            c[j] += k[j];
        }
    }
    latencies.sort_by(f64::total_cmp);
    LoadReport {
        requests,
        ok: c[0],
        client_errors: c[1],
        server_errors: c[2],
        dropped: c[3] + requests.saturating_sub(c.iter().sum()),
        latencies,
        wall,
    }
}
