//! `hirad view --serve`: the viewer page over HTTP on a local address (`tiny_http`). Exactly two
//! things are served: the page (`/`, `/index.html`, `/viewer.html`) and the solution's glb
//! (`/NAME.glb`), both held in memory; the file system is never read by request. Paths that
//! climb (`..`, also percent-encoded), hold a backslash or NUL, or are not origin paths
//! (`//host/…`, `http://…`) are refused (403); every other path is 404; methods other than
//! GET and HEAD get 405. The default address is 127.0.0.1 with a port the system chooses. On a
//! loopback address a request must name a loopback host (`localhost`, `127.x.y.z`, `[::1]`)
//! with the bound port in its `Host` header (421 otherwise), so that a web page whose name
//! is made to resolve to 127.0.0.1 (DNS rebinding) cannot read the solution.

use std::net::SocketAddr;

/// Default of `--serve` without a value: loopback, any free port.
pub const DEFAULT_ADDR: &str = "127.0.0.1:0";

/// What a request path resolves to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Route {
    /// The viewer page.
    Page,
    /// The glb.
    Glb,
    /// A climbing or non-origin path (403).
    Refused,
    /// Anything else (404).
    NotFound,
}

/// `PORT`, `IP:PORT` or `[IPv6]:PORT` (a bare port binds 127.0.0.1).
pub fn parse_addr(s: &str) -> Result<SocketAddr, String> {
    let s = s.trim();
    if let Ok(port) = s.parse::<u16>() {
        return Ok(SocketAddr::from(([127, 0, 0, 1], port)));
    }
    s.parse().map_err(|_| {
        format!("expected PORT, IP:PORT or [IPv6]:PORT (e.g. 127.0.0.1:8000), got '{s}'")
    })
}

/// Percent-decode a path; `None` for a malformed escape.
fn percent_decode(s: &str) -> Option<Vec<u8>> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    Some(out)
}

/// Resolve a request target (as sent: not normalised) against the two served names.
pub fn route(target: &str, glb_name: &str) -> Route {
    let path = target.split(['?', '#']).next().unwrap_or("");
    if !path.starts_with('/') || path.starts_with("//") {
        return Route::Refused;
    }
    let Some(decoded) = percent_decode(path) else {
        return Route::Refused;
    };
    if decoded.contains(&b'\\') || decoded.contains(&0) {
        return Route::Refused;
    }
    let Ok(decoded) = String::from_utf8(decoded) else {
        return Route::Refused;
    };
    if decoded.split('/').any(|seg| seg == "..") || decoded.starts_with("//") {
        return Route::Refused;
    }
    match decoded.as_str() {
        "/" | "/index.html" | "/viewer.html" => Route::Page,
        p if p.strip_prefix('/') == Some(glb_name) => Route::Glb,
        _ => Route::NotFound,
    }
}

/// The `Host` header `host` may reach a server bound to `bound`: any host on a non-loopback
/// address; on a loopback one, a loopback name with the bound port.
pub fn host_allowed(host: Option<&str>, bound: SocketAddr) -> bool {
    if !bound.ip().is_loopback() {
        return true;
    }
    let Some(host) = host.map(str::trim) else {
        return false;
    };
    let (name, port) = match host.rsplit_once(':') {
        Some((n, p)) if !n.is_empty() && (!n.contains(':') || n.ends_with(']')) => (n, p),
        _ => return false,
    };
    if port.parse::<u16>() != Ok(bound.port()) {
        return false;
    }
    let name = name.to_ascii_lowercase();
    name == "localhost"
        || name == "[::1]"
        || name
            .parse::<std::net::Ipv4Addr>()
            .is_ok_and(|ip| ip.is_loopback())
}

fn header(name: &str, value: &str) -> tiny_http::Header {
    tiny_http::Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("ASCII header")
}

/// Bind `addr`, print the page's URL on stdout, and answer requests until the process ends.
pub fn serve(addr: SocketAddr, html: String, glb: Vec<u8>, glb_name: &str) -> anyhow::Result<()> {
    let server = tiny_http::Server::http(addr)
        .map_err(|e| anyhow::anyhow!("cannot listen on {addr}: {e}"))?;
    let bound = server
        .server_addr()
        .to_ip()
        .ok_or_else(|| anyhow::anyhow!("the server has no IP address"))?;
    // The URL is the command's result (with port 0 the only way to learn the port): printed
    // even with -q.
    println!("http://{bound}/");
    use std::io::Write;
    std::io::stdout().flush()?;
    if !bound.ip().is_loopback() {
        tracing::warn!("serving on {bound}: reachable from other machines");
    }
    for req in server.incoming_requests() {
        let method = req.method().clone();
        let route = route(req.url(), glb_name);
        tracing::info!("{method} {} -> {route:?}", req.url());
        let host = req
            .headers()
            .iter()
            .find(|h| h.field.equiv("Host"))
            .map(|h| h.value.as_str().to_string());
        let (code, body, ctype): (u16, &[u8], &str) = match (&method, route) {
            _ if !host_allowed(host.as_deref(), bound) => {
                (421, b"421 not a loopback host\n", "text/plain")
            }
            (tiny_http::Method::Get | tiny_http::Method::Head, Route::Page) => {
                (200, html.as_bytes(), "text/html; charset=utf-8")
            }
            (tiny_http::Method::Get | tiny_http::Method::Head, Route::Glb) => {
                (200, &glb, "model/gltf-binary")
            }
            (tiny_http::Method::Get | tiny_http::Method::Head, Route::Refused) => {
                (403, b"403 refused\n", "text/plain")
            }
            (tiny_http::Method::Get | tiny_http::Method::Head, Route::NotFound) => {
                (404, b"404 not found\n", "text/plain")
            }
            _ => (405, b"405 only GET and HEAD\n", "text/plain"),
        };
        let body = if method == tiny_http::Method::Head {
            &[][..]
        } else {
            body
        };
        let resp = tiny_http::Response::from_data(body)
            .with_status_code(code)
            .with_header(header("Content-Type", ctype))
            .with_header(header("X-Content-Type-Options", "nosniff"))
            .with_header(header("Cache-Control", "no-store"));
        if let Err(e) = req.respond(resp) {
            tracing::debug!("response not sent: {e}");
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn routes_serve_only_the_page_and_the_glb() {
        let r = |t| route(t, "solution.glb");
        assert_eq!(r("/"), Route::Page);
        assert_eq!(r("/viewer.html?x=1#y"), Route::Page);
        assert_eq!(r("/solution.glb"), Route::Glb);
        assert_eq!(r("/solution%2eglb"), Route::Glb);
        for bad in [
            "/../Cargo.toml",
            "/%2e%2e/Cargo.toml",
            "/%2E%2E%2fCargo.toml",
            "/a/../solution.glb",
            "//etc/passwd",
            "http://x/solution.glb",
            "*",
            "/..%5cCargo.toml",
            "/%zz",
        ] {
            assert_eq!(r(bad), Route::Refused, "{bad}");
        }
        for missing in ["/etc/passwd", "/Cargo.toml", "/solution.glb/", "/index.htm"] {
            assert_eq!(r(missing), Route::NotFound, "{missing}");
        }
    }

    #[test]
    fn loopback_servers_answer_loopback_hosts_only() {
        let lo: SocketAddr = "127.0.0.1:8000".parse().unwrap();
        for ok in [
            "127.0.0.1:8000",
            "localhost:8000",
            "LOCALHOST:8000",
            "[::1]:8000",
        ] {
            assert!(host_allowed(Some(ok), lo), "{ok}");
        }
        for bad in [
            None,
            Some("evil.example:8000"),
            Some("127.0.0.1"),
            Some("127.0.0.1:8001"),
            Some("localhost.evil.example:8000"),
            Some(":8000"),
        ] {
            assert!(!host_allowed(bad, lo), "{bad:?}");
        }
        let any: SocketAddr = "0.0.0.0:8000".parse().unwrap();
        assert!(host_allowed(Some("viewer.lab:8000"), any));
    }

    #[test]
    fn bare_port_binds_loopback() {
        assert_eq!(parse_addr("8000").unwrap().to_string(), "127.0.0.1:8000");
        assert_eq!(parse_addr("[::1]:0").unwrap().to_string(), "[::1]:0");
        assert!(parse_addr("localhost").is_err());
    }
}
