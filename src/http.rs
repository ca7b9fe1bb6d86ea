//! The small local web server behind `annotate` and `study serve` (issue 27's promises):
//! - loopback only unless told otherwise;
//! - one event loop (mio) over non-blocking sockets, no thread per connection: at most
//!   [`Limits::connections`] are held (fewer when the open-file limit is lower), and when full
//!   the connection idle longest is dropped for the new one, so a flood of idle or stalled
//!   connections never shuts out a real client, and nothing panics when resources run out
//!   (refusals are reported once through the notice callback);
//! - deadlines on a request's headers and on its body, bounded header and body sizes;
//! - `Host` must be `localhost` or an IP literal (a DNS-rebinding page's name is refused);
//!   a POST needs a same-origin `Origin` and a JSON body (`Content-Type: application/json`),
//!   so no cross-site form or page can write;
//! - handlers run one at a time in the loop (each answer is on disk before the next request
//!   is read) and map a parsed request to a reply; every reply closes its connection;
//! - slow work (a model fit) is handed off the loop as an [`Answer::Later`] to at most
//!   [`WORKERS`] threads with at most [`QUEUED`] waiting (more are refused with 503), so a
//!   flood of slow requests never delays anyone else's answer.

use std::collections::HashMap;
use std::io::{Read, Write};
use std::net::{SocketAddr, ToSocketAddrs};
use std::path::Path;
use std::time::{Duration, Instant};

use mio::net::{TcpListener, TcpStream};
use mio::{Events, Interest, Poll, Token};
use serde_json::Value;
use thiserror::Error;

/// Largest request body read (1 MiB); a longer one is refused.
const MAX_BODY: usize = 1 << 20;
/// Largest request head (request line and headers).
const MAX_HEAD: usize = 16 << 10;

/// Bytes of replies made for one client (not shared with others) that may wait to be sent,
/// over all connections: past it a new reply is a short 503. Shared bodies (a model, a page)
/// cost nothing per client.
pub const MAX_QUEUED: usize = 256 << 20;

/// Threads running [`Answer::Later`] jobs.
pub const WORKERS: usize = 2;
/// [`Answer::Later`] jobs waiting for a worker; one more is refused (503).
pub const QUEUED: usize = 16;

/// What the server holds to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Connections held at once (capped again by the open-file limit).
    pub connections: usize,
    /// Time from accepting a connection to its complete request head.
    pub head: Duration,
    /// Time from the head to the complete body.
    pub body: Duration,
    /// Time to send a reply.
    pub write: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            connections: 4096,
            head: Duration::from_secs(5),
            body: Duration::from_secs(10),
            write: Duration::from_secs(30),
        }
    }
}

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
pub struct Server {
    listener: std::net::TcpListener,
    limits: Limits,
}

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

/// A reply: a status, a body and its type. The body is shared, not copied: a big answer made
/// once (a model's 19 MB of appearance) is sent to any number of clients from one buffer.
#[derive(Clone, Debug, PartialEq)]
pub struct Reply {
    /// HTTP status.
    pub status: u16,
    /// The body.
    pub body: Body,
    /// Its MIME type.
    pub mime: &'static str,
}

/// A reply's bytes, shared between the replies that send them.
pub type Body = std::sync::Arc<[u8]>;

impl Reply {
    /// 200 with `body` of type `mime`.
    pub fn ok(body: impl Into<Body>, mime: &'static str) -> Self {
        Reply {
            status: 200,
            body: body.into(),
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
            body: why.into().into_bytes().into(),
            mime: "text/plain; charset=utf-8",
        }
    }

    /// Whether the status is a success.
    pub fn is_ok(&self) -> bool {
        self.status < 400
    }
}

/// A handler's answer: a reply now, or slow work to run off the event loop whose reply is
/// sent when it is done.
pub enum Answer<'a> {
    /// The reply.
    Now(Reply),
    /// Work for a worker thread (bounded: see [`QUEUED`]).
    Later(Box<dyn FnOnce() -> Reply + Send + 'a>),
}

impl From<Reply> for Answer<'_> {
    fn from(reply: Reply) -> Self {
        Answer::Now(reply)
    }
}

/// A job handed to a worker: whose it is and what to run.
type Job<'a> = (Token, Box<dyn FnOnce() -> Reply + Send + 'a>);

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
        let listener = std::net::TcpListener::bind(first).map_err(|e| bind(e.to_string()))?;
        deepen_backlog(&listener);
        listener
            .set_nonblocking(true)
            .map_err(|e| bind(e.to_string()))?;
        Ok(Server {
            listener,
            limits: Limits::default(),
        })
    }

    /// The same server holding to other limits.
    pub fn with_limits(mut self, limits: Limits) -> Self {
        self.limits = limits;
        self
    }

    /// The server's address as a URL ending in `/`.
    pub fn url(&self) -> String {
        match self.listener.local_addr() {
            Ok(a) => format!("http://{a}/"),
            Err(_) => "http://localhost/".into(),
        }
    }

    /// Answers requests with `handle` until `stop` returns true (checked at least every
    /// 100 ms); `notice` hears, once per episode, of connections refused or dropped for want
    /// of resources.
    pub fn serve<'a>(
        &self,
        mut handle: impl FnMut(&Request) -> Answer<'a>,
        stop: impl Fn() -> bool,
        mut notice: impl FnMut(String),
    ) {
        let Ok(mut looped) = EventLoop::new(self, &mut notice) else {
            return;
        };
        let Ok(waker) = mio::Waker::new(looped.poll.registry(), WAKER) else {
            return;
        };
        let waker = std::sync::Arc::new(waker);
        let (jobs, queue) = std::sync::mpsc::sync_channel::<Job<'a>>(QUEUED);
        let queue = std::sync::Mutex::new(queue);
        let (done, finished) = std::sync::mpsc::channel::<(Token, Reply)>();
        std::thread::scope(|scope| {
            for _ in 0..WORKERS {
                let (queue, done, waker) = (&queue, done.clone(), waker.clone());
                scope.spawn(move || {
                    loop {
                        let job = queue.lock().unwrap_or_else(|e| e.into_inner()).recv();
                        let Ok((token, work)) = job else { return };
                        let reply = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work))
                            .unwrap_or_else(|_| Reply::error(500, "the request failed"));
                        if done.send((token, reply)).is_err() {
                            return;
                        }
                        let _ = waker.wake();
                    }
                });
            }
            while !stop() {
                looped.turn(&mut handle, &jobs, &finished, &mut notice);
            }
            // Closing the queue ends the workers once their current job is done.
            drop(jobs);
        });
    }
}

const LISTENER: Token = Token(usize::MAX);
/// Wakes the loop when a worker has finished a job.
const WAKER: Token = Token(usize::MAX - 1);

/// Where a connection is.
enum Stage {
    /// Reading the request (head and body).
    Reading,
    /// Waiting for a worker's reply ([`Answer::Later`]).
    Waiting,
    /// Sending the reply; `usize` bytes sent.
    Writing(Outgoing, usize),
    /// Reply sent and the write side shut: reading what the peer still sends (a body
    /// refused before it was read), so that closing does not reset the reply away.
    Draining,
}

struct Connection {
    stream: TcpStream,
    input: Vec<u8>,
    stage: Stage,
    /// When the current stage must be done.
    deadline: Instant,
    /// Whether the head has been read (the deadline then covers the body).
    head_done: bool,
    /// Bytes of its reply counted in [`EventLoop::queued`].
    owned: usize,
}

struct EventLoop {
    poll: Poll,
    events: Events,
    listener: TcpListener,
    connections: HashMap<Token, Connection>,
    next: usize,
    limits: Limits,
    capacity: usize,
    port: u16,
    /// A resource notice was given and not yet cleared.
    noticed: bool,
    /// Bytes of unshared replies waiting to be sent ([`MAX_QUEUED`]).
    queued: usize,
}

/// `reply` ready to send, counted in `queued` — or a 503 instead when it would take the
/// replies waiting past [`MAX_QUEUED`]; gives the bytes counted.
fn admit(queued: &mut usize, reply: Reply) -> (Outgoing, usize) {
    let own = |out: &Outgoing| {
        out.head.len() + if std::sync::Arc::strong_count(&out.body) == 1 { out.body.len() } else { 0 }
    };
    let mut out = response(reply);
    if *queued + own(&out) > MAX_QUEUED {
        out = response(Reply::error(503, "busy: too many replies are waiting to be read; try again shortly"));
    }
    let owned = own(&out);
    *queued += owned;
    (out, owned)
}

/// Connections the kernel completes and queues before the server accepts them. The standard
/// library listens with 128: a burst of connections (a flood, or a page's many fetches)
/// fills that before the server thread is scheduled, and each SYN past it is dropped and
/// retried by its client only a second later — a normal client kept waiting. (Linux caps
/// it at `net.core.somaxconn`, 4096 by default.)
pub const BACKLOG: i32 = 4096;

/// Listens on `listener` again with [`BACKLOG`]: on a listening socket `listen` only changes
/// the queue's length. Best effort: where it fails the standard library's 128 stays.
fn deepen_backlog(listener: &std::net::TcpListener) {
    #[cfg(unix)]
    {
        use std::os::fd::AsRawFd;
        // SAFETY: listen takes the descriptor `listener` owns and keeps open while it lives.
        unsafe {
            libc::listen(listener.as_raw_fd(), BACKLOG);
        }
    }
}

/// Connections the open-file limit leaves room for (64 descriptors kept for files).
fn descriptor_room() -> usize {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes one rlimit into the struct it is given.
    let ok = unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) } == 0;
    if ok {
        (limit.rlim_cur as usize).saturating_sub(64).max(16)
    } else {
        1024
    }
}

impl EventLoop {
    fn new(server: &Server, notice: &mut impl FnMut(String)) -> std::io::Result<Self> {
        let poll = Poll::new().inspect_err(|e| notice(format!("cannot poll: {e}")))?;
        let std_listener = server
            .listener
            .try_clone()
            .inspect_err(|e| notice(format!("cannot listen: {e}")))?;
        let port = std_listener.local_addr().map(|a| a.port()).unwrap_or(0);
        let mut listener = TcpListener::from_std(std_listener);
        poll.registry()
            .register(&mut listener, LISTENER, Interest::READABLE)?;
        Ok(EventLoop {
            poll,
            events: Events::with_capacity(1024),
            listener,
            connections: HashMap::new(),
            next: 0,
            limits: server.limits,
            capacity: server.limits.connections.min(descriptor_room()),
            port,
            noticed: false,
            queued: 0,
        })
    }

    fn turn<'a>(
        &mut self,
        handle: &mut impl FnMut(&Request) -> Answer<'a>,
        jobs: &std::sync::mpsc::SyncSender<Job<'a>>,
        finished: &std::sync::mpsc::Receiver<(Token, Reply)>,
        notice: &mut impl FnMut(String),
    ) {
        if let Err(e) = self
            .poll
            .poll(&mut self.events, Some(Duration::from_millis(100)))
        {
            if e.kind() != std::io::ErrorKind::Interrupted {
                std::thread::sleep(Duration::from_millis(10));
            }
            return;
        }
        let ready: Vec<Token> = self.events.iter().map(|e| e.token()).collect();
        for token in ready {
            if token == LISTENER {
                self.accept(notice);
            } else if token != WAKER {
                self.progress(token, handle, jobs);
            }
        }
        // Workers' replies, each sent as soon as it is there (a connection that timed out
        // meanwhile is gone, and its reply with it).
        while let Ok((token, reply)) = finished.try_recv() {
            if let Some(c) = self.connections.get_mut(&token)
                && matches!(c.stage, Stage::Waiting)
            {
                let (out, owned) = admit(&mut self.queued, reply);
                c.stage = Stage::Writing(out, 0);
                c.owned = owned;
                c.deadline = Instant::now() + self.limits.write;
                self.progress(token, handle, jobs);
            }
        }
        self.expire();
        if self.noticed && self.connections.len() < self.capacity * 9 / 10 {
            self.noticed = false;
        }
    }

    fn tell(&mut self, notice: &mut impl FnMut(String), what: String) {
        if !self.noticed {
            self.noticed = true;
            notice(what);
        }
    }

    /// Accepts every waiting connection; when full, drops the one idle longest for it.
    fn accept(&mut self, notice: &mut impl FnMut(String)) {
        loop {
            if self.connections.len() >= self.capacity {
                self.tell(
                    notice,
                    format!(
                        "{} connections held (the most allowed): dropping the idlest for each new one",
                        self.connections.len()
                    ),
                );
                self.drop_idlest();
            }
            match self.listener.accept() {
                Ok((mut stream, _)) => {
                    let token = Token(self.next);
                    self.next = (self.next + 1) % (usize::MAX - 2);
                    if self
                        .poll
                        .registry()
                        .register(&mut stream, token, Interest::READABLE | Interest::WRITABLE)
                        .is_err()
                    {
                        continue;
                    }
                    self.connections.insert(
                        token,
                        Connection {
                            stream,
                            input: Vec::new(),
                            stage: Stage::Reading,
                            deadline: Instant::now() + self.limits.head,
                            head_done: false,
                            owned: 0,
                        },
                    );
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    // Out of descriptors or memory: make room, say so once, try later.
                    self.tell(notice, format!("cannot accept a connection: {e}"));
                    self.drop_idlest();
                    return;
                }
            }
        }
    }

    /// Drops the reading connection whose deadline is nearest (the one idle longest).
    fn drop_idlest(&mut self) {
        let idlest = self
            .connections
            .iter()
            .filter(|(_, c)| !matches!(c.stage, Stage::Writing(..) | Stage::Waiting))
            .min_by_key(|(_, c)| (!matches!(c.stage, Stage::Draining), c.head_done, c.deadline))
            .map(|(t, _)| *t);
        if let Some(t) = idlest {
            self.close(t);
        }
    }

    fn close(&mut self, token: Token) {
        if let Some(mut c) = self.connections.remove(&token) {
            self.queued -= c.owned;
            let _ = self.poll.registry().deregister(&mut c.stream);
        }
    }

    fn expire(&mut self) {
        let now = Instant::now();
        let late: Vec<Token> = self
            .connections
            .iter()
            .filter(|(_, c)| c.deadline <= now)
            .map(|(t, _)| *t)
            .collect();
        for t in late {
            self.close(t);
        }
    }

    /// Reads what has arrived, answers a complete request, sends what can be sent.
    fn progress<'a>(
        &mut self,
        token: Token,
        handle: &mut impl FnMut(&Request) -> Answer<'a>,
        jobs: &std::sync::mpsc::SyncSender<Job<'a>>,
    ) {
        let Some(c) = self.connections.get_mut(&token) else {
            return;
        };
        if matches!(c.stage, Stage::Reading) {
            let mut buf = [0u8; 8192];
            loop {
                match c.stream.read(&mut buf) {
                    Ok(0) => {
                        // The peer closed before a whole request.
                        self.close(token);
                        return;
                    }
                    Ok(n) => {
                        c.input.extend_from_slice(&buf[..n]);
                        if c.input.len() > MAX_HEAD + MAX_BODY {
                            break;
                        }
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(_) => {
                        self.close(token);
                        return;
                    }
                }
            }
            let reply = match parse(&c.input, self.port) {
                Parsed::Incomplete { head_done } => {
                    if head_done && !c.head_done {
                        c.head_done = true;
                        c.deadline = Instant::now() + self.limits.body;
                    }
                    None
                }
                Parsed::Refused(reply) => Some(reply),
                Parsed::Request(request) => match handle(&request) {
                    Answer::Now(reply) => Some(reply),
                    Answer::Later(work) => match jobs.try_send((token, work)) {
                        Ok(()) => {
                            c.stage = Stage::Waiting;
                            c.deadline = Instant::now() + self.limits.write;
                            return;
                        }
                        Err(_) => Some(Reply::error(
                            503,
                            format!("busy: {QUEUED} slow requests are waiting; try again shortly"),
                        )),
                    },
                },
            };
            let Some(reply) = reply else { return };
            let (out, owned) = admit(&mut self.queued, reply);
            c.stage = Stage::Writing(out, 0);
            c.owned = owned;
            c.deadline = Instant::now() + self.limits.write;
        }
        if let Stage::Writing(out, sent) = &mut c.stage {
            while *sent < out.len() {
                match c.stream.write(out.from(*sent)) {
                    Ok(0) => break,
                    Ok(n) => *sent += n,
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(_) => break,
                }
            }
            let _ = c.stream.flush();
            let _ = c.stream.shutdown(std::net::Shutdown::Write);
            c.stage = Stage::Draining;
            self.queued -= std::mem::take(&mut c.owned);
            c.deadline = Instant::now() + Duration::from_secs(2);
        }
        if matches!(c.stage, Stage::Draining) {
            let mut buf = [0u8; 8192];
            loop {
                match c.stream.read(&mut buf) {
                    Ok(0) => break,
                    Ok(_) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => break,
                }
            }
            self.close(token);
        }
    }
}

/// What the bytes read so far make.
enum Parsed {
    /// Not yet a whole request.
    Incomplete {
        /// The head is complete (the body is still coming).
        head_done: bool,
    },
    /// A request refused before any handler sees it.
    Refused(Reply),
    /// A whole request, checked.
    Request(Request),
}

/// Whether `host` (a `Host` header) names this server without a DNS name: `localhost` or
/// an IP literal, with this port or none.
fn host_allowed(host: &str, port: u16) -> bool {
    let (name, given_port) = match host.rsplit_once(':') {
        Some((n, p)) if !n.ends_with(':') && !p.contains(']') => (n, Some(p)),
        _ => (host, None),
    };
    if let Some(p) = given_port
        && p.parse::<u16>() != Ok(port)
    {
        return false;
    }
    let name = name.trim_start_matches('[').trim_end_matches(']');
    name.eq_ignore_ascii_case("localhost") || name.parse::<std::net::IpAddr>().is_ok()
}

fn parse(input: &[u8], port: u16) -> Parsed {
    let mut headers = [httparse::EMPTY_HEADER; 64];
    let mut head = httparse::Request::new(&mut headers);
    let refuse = |status, why: &str| Parsed::Refused(Reply::error(status, why));
    let head_len = match head.parse(input) {
        Ok(httparse::Status::Complete(n)) => n,
        Ok(httparse::Status::Partial) if input.len() > MAX_HEAD => {
            return refuse(431, "request head too large");
        }
        Ok(httparse::Status::Partial) => return Parsed::Incomplete { head_done: false },
        Err(e) => return refuse(400, &format!("malformed request: {e}")),
    };
    let header = |name: &str| {
        head.headers
            .iter()
            .find(|h| h.name.eq_ignore_ascii_case(name))
            .map(|h| String::from_utf8_lossy(h.value).trim().to_owned())
    };
    let post = match head.method {
        Some("GET") => false,
        Some("POST") => true,
        _ => return refuse(405, "only GET and POST"),
    };
    let Some(host) = header("host") else {
        return refuse(400, "no Host header");
    };
    if !host_allowed(&host, port) {
        return refuse(
            421,
            &format!("Host {host:?} is not this server (localhost or an IP address only)"),
        );
    }
    let length = match header("content-length").map(|v| v.parse::<usize>()) {
        None => 0,
        Some(Ok(n)) if n <= MAX_BODY => n,
        Some(Ok(_)) => return refuse(413, "request body over 1 MiB"),
        Some(Err(_)) => return refuse(400, "bad Content-Length"),
    };
    if header("transfer-encoding").is_some() {
        return refuse(411, "chunked bodies are not taken; send Content-Length");
    }
    if post {
        let origin = header("origin");
        if origin.as_deref() != Some(format!("http://{host}").as_str()) {
            return refuse(
                403,
                &format!("a POST needs the page's own Origin (http://{host}), not {origin:?}"),
            );
        }
        let json = header("content-type").is_some_and(|t| {
            t.split(';')
                .next()
                .is_some_and(|m| m.trim().eq_ignore_ascii_case("application/json"))
        });
        if !json {
            return refuse(415, "a POST body must be application/json");
        }
    }
    if input.len() < head_len + length {
        return Parsed::Incomplete { head_done: true };
    }
    let target = head.path.unwrap_or("/");
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let Some(path) = percent_decode(path) else {
        return refuse(400, "bad path encoding");
    };
    let Some(query) = parse_query(query) else {
        return refuse(400, "bad query encoding");
    };
    let Ok(body) = String::from_utf8(input[head_len..head_len + length].to_vec()) else {
        return refuse(400, "the body is not UTF-8");
    };
    Parsed::Request(Request {
        post,
        path,
        query,
        body,
    })
}

/// A reply being sent: its head, then its shared body (never copied per client).
struct Outgoing {
    head: Vec<u8>,
    body: Body,
}

impl Outgoing {
    fn len(&self) -> usize {
        self.head.len() + self.body.len()
    }

    /// The bytes from `at` on, up to the end of the part `at` is in.
    fn from(&self, at: usize) -> &[u8] {
        match at.checked_sub(self.head.len()) {
            None => &self.head[at..],
            Some(b) => &self.body[b..],
        }
    }
}

/// An HTTP/1.1 reply that closes its connection.
fn response(reply: Reply) -> Outgoing {
    let reason = match reply.status {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        409 => "Conflict",
        411 => "Length Required",
        413 => "Payload Too Large",
        415 => "Unsupported Media Type",
        421 => "Misdirected Request",
        431 => "Request Header Fields Too Large",
        _ if reply.status < 400 => "OK",
        _ if reply.status < 500 => "Refused",
        _ => "Server Error",
    };
    let head = format!(
        "HTTP/1.1 {} {reason}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        reply.status,
        reply.mime,
        reply.body.len()
    )
    .into_bytes();
    Outgoing {
        head,
        body: reply.body,
    }
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

/// Escapes every byte but ASCII letters, digits and `-_.~` as `%XX` (for a query value).
pub fn percent_encode(s: &str) -> String {
    s.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
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
