//! The small local web server behind `annotate` and `study serve`: loopback only unless told
//! otherwise, one request at a time (each answer is written before the next is read), bounded
//! request bodies, and handlers that map a parsed request to a reply.

use std::io::Read;
use std::net::{SocketAddr, ToSocketAddrs};
use std::path::Path;
use std::time::Duration;

use serde_json::Value;
use thiserror::Error;

/// Largest request body read (1 MiB); a longer one is cut and fails to parse.
const MAX_BODY: u64 = 1 << 20;

/// What can go wrong starting a server.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum HttpError {
    /// A non-loopback address without permission.
    #[error(
        "{0} is not a loopback address: the page would be reachable from other machines; pass --allow-remote if that is meant"
    )]
    NotLoopback(SocketAddr),
    /// The address cannot be bound.
    #[error("cannot listen on {addr}: {reason}")]
    Bind {
        /// The address.
        addr: String,
        /// Why.
        reason: String,
    },
}

/// A bound server.
pub struct Server(tiny_http::Server);

/// A request as the handlers see it.
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    /// True for POST, false for GET (other methods are refused before a handler sees them).
    pub post: bool,
    /// The path, without the query.
    pub path: String,
    /// The query's `key=value` pairs, decoded.
    pub query: Vec<(String, String)>,
    /// The body (at most 1 MiB), for POST.
    pub body: String,
}

impl Request {
    /// The decoded value of query parameter `key`.
    pub fn param(&self, key: &str) -> Option<&str> {
        self.query
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// A reply: a status, a body and its type.
#[derive(Clone, Debug, PartialEq)]
pub struct Reply {
    /// HTTP status.
    pub status: u16,
    /// The body.
    pub body: Vec<u8>,
    /// Its MIME type.
    pub mime: &'static str,
}

impl Reply {
    /// 200 with `body` of type `mime`.
    pub fn ok(body: Vec<u8>, mime: &'static str) -> Self {
        Reply {
            status: 200,
            body,
            mime,
        }
    }

    /// 200 with a JSON body.
    pub fn json(v: Value) -> Self {
        Reply::ok(v.to_string().into_bytes(), "application/json")
    }

    /// An error status with the reason as plain text.
    pub fn error(status: u16, why: impl Into<String>) -> Self {
        Reply {
            status,
            body: why.into().into_bytes(),
            mime: "text/plain; charset=utf-8",
        }
    }

    /// Whether the status is a success.
    pub fn is_ok(&self) -> bool {
        self.status < 400
    }
}

impl Server {
    /// Binds `addr`; a non-loopback address needs `allow_remote`.
    pub fn bind(addr: &str, allow_remote: bool) -> Result<Self, HttpError> {
        let bind = |reason: String| HttpError::Bind {
            addr: addr.into(),
            reason,
        };
        let resolved: Vec<SocketAddr> = addr
            .to_socket_addrs()
            .map_err(|e| bind(e.to_string()))?
            .collect();
        let first = *resolved.first().ok_or_else(|| bind("no address".into()))?;
        if let Some(a) = resolved.iter().find(|a| !a.ip().is_loopback())
            && !allow_remote
        {
            return Err(HttpError::NotLoopback(*a));
        }
        tiny_http::Server::http(first)
            .map(Server)
            .map_err(|e| bind(e.to_string()))
    }

    /// The server's address as a URL ending in `/`.
    pub fn url(&self) -> String {
        match self.0.server_addr().to_ip() {
            Some(a) => format!("http://{a}/"),
            None => "http://localhost/".into(),
        }
    }

    /// Answers requests with `handle` until `stop` returns true (checked between requests and
    /// every 100 ms).
    pub fn serve(&self, mut handle: impl FnMut(&Request) -> Reply, stop: impl Fn() -> bool) {
        while !stop() {
            match self.0.recv_timeout(Duration::from_millis(100)) {
                Ok(Some(request)) => answer(request, &mut handle),
                Ok(None) => {}
                Err(_) => break,
            }
        }
    }
}

fn answer(mut request: tiny_http::Request, handle: &mut impl FnMut(&Request) -> Reply) {
    let url = request.url().to_owned();
    let (path, query) = url.split_once('?').unwrap_or((&url, ""));
    let post = match request.method() {
        tiny_http::Method::Get => Some(false),
        tiny_http::Method::Post => Some(true),
        _ => None,
    };
    let mut body = String::new();
    let reply = match (post, percent_decode(path)) {
        (None, _) => Reply::error(405, "only GET and POST"),
        (_, None) => Reply::error(400, "bad path encoding"),
        (Some(post), Some(path)) => {
            let read = if post {
                request
                    .as_reader()
                    .take(MAX_BODY)
                    .read_to_string(&mut body)
                    .map(|_| ())
            } else {
                Ok(())
            };
            match (read, parse_query(query)) {
                (Err(e), _) => Reply::error(400, e.to_string()),
                (_, None) => Reply::error(400, "bad query encoding"),
                (Ok(()), Some(query)) => handle(&Request {
                    post,
                    path,
                    query,
                    body,
                }),
            }
        }
    };
    let response = tiny_http::Response::from_data(reply.body)
        .with_status_code(reply.status)
        .with_header(
            tiny_http::Header::from_bytes("Content-Type", reply.mime).expect("valid header"),
        )
        .with_header(
            tiny_http::Header::from_bytes("Cache-Control", "no-store").expect("valid header"),
        );
    let _ = request.respond(response);
}

fn parse_query(query: &str) -> Option<Vec<(String, String)>> {
    query
        .split('&')
        .filter(|kv| !kv.is_empty())
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap_or((kv, ""));
            Some((
                percent_decode(&k.replace('+', " "))?,
                percent_decode(&v.replace('+', " "))?,
            ))
        })
        .collect()
}

/// The MIME type of a served file, by extension.
pub fn mime(name: &str) -> &'static str {
    match Path::new(name)
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => "image/png",
        Some("jpg" | "jpeg") => "image/jpeg",
        Some("mp4") => "video/mp4",
        _ => "application/octet-stream",
    }
}

/// Decodes `%XX` escapes (UTF-8); `None` for a malformed escape or invalid UTF-8.
pub fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_escapes_and_refuses_malformed_ones() {
        assert_eq!(percent_decode("a%20b%C3%A9").as_deref(), Some("a bé"));
        assert_eq!(percent_decode("%2"), None);
        assert_eq!(percent_decode("%zz"), None);
        assert_eq!(percent_decode("%C3"), None);
        let q = parse_query("viewer=v%2001&token=ab+c&flag").unwrap();
        assert_eq!(
            q,
            vec![
                ("viewer".into(), "v 01".into()),
                ("token".into(), "ab c".into()),
                ("flag".into(), String::new())
            ]
        );
    }
}
