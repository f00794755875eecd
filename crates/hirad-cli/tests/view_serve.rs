//! `hirad view SOLUTION.glb --serve`: binds 127.0.0.1 by default on the port the system
//! chooses, serves the viewer page and the glb, and nothing else (no listing, no `..`, no
//! other file). Requests are written by hand on a TCP socket so the paths reach the server
//! exactly as typed (an HTTP client would normalise `..`).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// The server process, killed when dropped.
struct Server {
    child: Child,
    url: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `hirad -q view GLB --serve [ADDR]`; waits for the URL line.
fn serve(glb: &Path, addr: Option<&str>) -> Server {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_hirad"));
    cmd.args(["-q", "view"]).arg(glb).arg("--serve");
    cmd.args(addr);
    let mut child = cmd.stdout(Stdio::piped()).spawn().unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    Server {
        child,
        url: line.trim().to_string(),
    }
}

/// A cornell box glb and, beside it, a file that must never be served.
fn fixture(dir: &Path) -> PathBuf {
    let glb = dir.join("cornell.glb");
    let r = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(["-q", "scene", "cornell", "--out"])
        .arg(&glb)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    std::fs::write(dir.join("secret.txt"), "SECRET-NEXT-TO-THE-GLB").unwrap();
    glb
}

/// `METHOD target` sent verbatim; returns (status, body).
fn request(url: &str, method: &str, target: &str) -> (u16, Vec<u8>) {
    let addr = url.trim_start_matches("http://").trim_end_matches('/');
    request_as(url, addr, method, target)
}

/// [`request`] with `host` in the `Host` header.
fn request_as(url: &str, host: &str, method: &str, target: &str) -> (u16, Vec<u8>) {
    let addr = url.trim_start_matches("http://").trim_end_matches('/');
    let mut s = TcpStream::connect(addr).unwrap();
    write!(
        s,
        "{method} {target} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut resp = Vec::new();
    s.read_to_end(&mut resp).unwrap();
    let head_end = resp
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a complete response");
    let head = String::from_utf8_lossy(&resp[..head_end]);
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, resp[head_end + 4..].to_vec())
}

#[test]
fn view_serve_binds_loopback_and_serves_the_page_and_its_glb() {
    let d = tempfile::tempdir().unwrap();
    let glb = fixture(d.path());
    let srv = serve(&glb, None);
    assert!(srv.url.starts_with("http://127.0.0.1:"), "{}", srv.url);
    assert!(
        !srv.url.ends_with(":0/"),
        "port 0 must print the chosen port"
    );
    let (code, page) = request(&srv.url, "GET", "/");
    assert_eq!(code, 200);
    let page = String::from_utf8(page).unwrap();
    assert!(page.contains("<canvas") && page.contains("const GLB_BASE64"));
    assert!(page.contains(r#""name":"cornell.glb""#));
    let (code, body) = request(&srv.url, "GET", "/cornell.glb");
    assert_eq!(code, 200);
    assert_eq!(body, std::fs::read(&glb).unwrap());
    let (code, body) = request(&srv.url, "HEAD", "/");
    assert_eq!((code, body.len()), (200, 0));
}

#[test]
fn view_serve_refuses_dotdot_absolute_and_unlisted_paths() {
    let d = tempfile::tempdir().unwrap();
    let glb = fixture(d.path());
    let srv = serve(&glb, Some("127.0.0.1:0"));
    for (target, want) in [
        ("/../Cargo.toml", 403),
        ("/../../Cargo.toml", 403),
        ("/%2e%2e/Cargo.toml", 403),
        ("/%2E%2E%2F%2e%2e%2fCargo.toml", 403),
        ("/..%5c..%5cCargo.toml", 403),
        ("//etc/passwd", 403),
        ("http://127.0.0.1/etc/passwd", 403),
        ("/etc/passwd", 404),
        ("/secret.txt", 404),
        ("/Cargo.toml", 404),
        ("/cornell.glb/", 404),
        ("/tmp/", 404),
    ] {
        let (code, body) = request(&srv.url, "GET", target);
        let body = String::from_utf8_lossy(&body);
        assert_eq!(code, want, "{target}: {body}");
        assert!(!body.contains("SECRET") && !body.contains("root:") && !body.contains("[package]"));
    }
    // `/` is the page, never a listing of the glb's directory.
    let (_, page) = request(&srv.url, "GET", "/");
    assert!(!String::from_utf8_lossy(&page).contains("secret.txt"));
    let (code, _) = request(&srv.url, "POST", "/");
    assert_eq!(code, 405);
    // DNS rebinding: a page of another name that resolves to 127.0.0.1 is not served.
    let port = srv.url.trim_end_matches('/').rsplit(':').next().unwrap();
    let (code, body) = request_as(
        &srv.url,
        &format!("evil.example:{port}"),
        "GET",
        "/cornell.glb",
    );
    assert_eq!(code, 421, "{}", String::from_utf8_lossy(&body));
    let (code, _) = request_as(&srv.url, &format!("localhost:{port}"), "GET", "/");
    assert_eq!(code, 200);
}

#[test]
fn view_serve_bare_port_is_loopback_and_a_bad_address_exits_2() {
    let d = tempfile::tempdir().unwrap();
    let glb = fixture(d.path());
    let srv = serve(&glb, Some("0"));
    assert!(srv.url.starts_with("http://127.0.0.1:"), "{}", srv.url);
    drop(srv);
    let r = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(["view"])
        .arg(&glb)
        .args(["--serve", "localhost:80:80"])
        .output()
        .unwrap();
    assert_eq!(r.status.code(), Some(2));
    let help = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(["view", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(
        help.contains("127.0.0.1") && help.contains("no directory listing"),
        "{help}"
    );
}
