//! A `kac serve` process on a loopback port for one test: started with flags, its first line read, killed when
//! dropped; and raw HTTP/1.1 over a TCP stream for what a client library would tidy away (`..` segments, NUL,
//! `Expect: 100-continue`, bodies sent a byte at a time).

#![allow(dead_code)]

use serde_json::Value;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

pub struct Server {
    pub child: Child,
    pub base: String,
    pub addr: String,
}

/// `kac serve` on a free loopback port and `data_dir` with `extra` flags, its standard output piped.
pub fn serve(data_dir: &Path, extra: &[&str]) -> Command {
    let (extra, faults) = super::faults::split(extra);
    let mut c = Command::new(env!("CARGO_BIN_EXE_kac"));
    c.args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
        .arg(data_dir)
        .args(extra)
        .envs(faults)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped());
    c
}

impl Server {
    /// Starts `kac serve` on `data_dir` with `extra` flags; panics if it does not print its address.
    pub fn start(data_dir: &Path, extra: &[&str]) -> Server {
        let mut child = serve(data_dir, extra).stderr(Stdio::inherit()).spawn().unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let v: Value = serde_json::from_str(&line).unwrap_or_else(|_| panic!("first line: {line}"));
        let addr = v["listening"].as_str().unwrap().to_string();
        Server { child, base: format!("http://{addr}"), addr }
    }
    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }
    /// One raw request (the bytes as given) and the whole answer as text, read until the server closes or
    /// `timeout` passes.
    pub fn raw(&self, request: &[u8], timeout: Duration) -> String {
        let mut s = TcpStream::connect(&self.addr).unwrap();
        s.set_read_timeout(Some(timeout)).unwrap();
        s.write_all(request).unwrap();
        let mut out = Vec::new();
        let _ = s.read_to_end(&mut out);
        String::from_utf8_lossy(&out).into_owned()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What a `kac serve` that refuses to start printed: its exit status and its standard error, within `timeout`.
pub fn refused_start(data_dir: &Path, extra: &[&str], timeout: Duration) -> (Option<i32>, String, String) {
    let mut child = serve(data_dir, extra).stderr(Stdio::piped()).spawn().unwrap();
    let t = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let (mut out, mut err) = (String::new(), String::new());
            child.stdout.take().unwrap().read_to_string(&mut out).unwrap();
            child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
            return (status.code(), out, err);
        }
        if t.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            let mut out = String::new();
            child.stdout.take().unwrap().read_to_string(&mut out).unwrap();
            return (None, out, "still running".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

pub fn agent() -> ureq::Agent {
    ureq::AgentBuilder::new().timeout(Duration::from_secs(120)).build()
}

/// (status, body as JSON or Null, headers we look at: content type, retry-after, etag).
pub struct Reply {
    pub status: u16,
    pub body: Value,
    pub content_type: String,
    pub retry_after: Option<String>,
    pub etag: Option<String>,
    pub raw: Vec<u8>,
}

pub fn reply(r: Result<ureq::Response, ureq::Error>) -> Reply {
    let resp = match r {
        Ok(r) => r,
        Err(ureq::Error::Status(_, r)) => r,
        Err(e) => panic!("transport error: {e}"),
    };
    let status = resp.status();
    let content_type = resp.header("content-type").unwrap_or("").to_string();
    let retry_after = resp.header("retry-after").map(str::to_string);
    let etag = resp.header("etag").map(str::to_string);
    let mut raw = vec![];
    resp.into_reader().read_to_end(&mut raw).unwrap();
    let body = serde_json::from_slice(&raw).unwrap_or(Value::Null);
    Reply { status, body, content_type, retry_after, etag, raw }
}

/// Asserts a problem document with this status and code.
pub fn assert_problem(r: &Reply, status: u16, code: &str) {
    assert_eq!(r.status, status, "{}", String::from_utf8_lossy(&r.raw));
    assert_eq!(r.content_type, "application/problem+json", "{}", String::from_utf8_lossy(&r.raw));
    assert_eq!(r.body["code"], code, "{}", r.body);
}
