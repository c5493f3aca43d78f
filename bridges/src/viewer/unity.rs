//! Unity without ROS: a server speaking the ROS-TCP-Endpoint protocol that Unity's
//! ROS-TCP-Connector uses (ROS 2 mode), so a Unity scene subscribes to `/joint_states` and
//! publishes commands against the twin directly.
//!
//! Protocol (the endpoint is the server; Unity connects): every frame is a u32 little-endian
//! length and a UTF-8 destination, then a u32 length and a payload. An empty destination is a
//! keepalive. Destinations starting with `__` are system commands whose payload is JSON (from
//! Unity followed by one byte the endpoint strips): from Unity `__subscribe {topic,
//! message_name}`, `__publish {topic, message_name, queue_size, latch}`, `__topic_list`; from
//! the endpoint `__handshake {version, metadata}` first, `__log`/`__warn`/`__error {text}` and
//! `__topic_list {topics, types}`. Other destinations are topics; payloads are the ROS 2 CDR
//! serialization of the message (encapsulation header first), as twin writes it. Services
//! (`__ros_service`, `__unity_service`, `__request`, `__response`) are refused with `__error`.
//!
//! Data flow: [`Server::start`] accepts clients on a thread; each client has a reader thread
//! (frames in) and a writer thread (a bounded queue out, so the simulation never blocks).
//! [`UnitySink`] is the recording's sink: a topic's messages are encoded for a client only
//! once it subscribed. Messages Unity publishes are queued ([`Server::take_client_messages`])
//! for [`super::SimHook`], which applies joint commands as for Foxglove.

use super::foxglove::ClientMessage;
use serde_json::{Value, json};
use std::collections::{HashMap, HashSet};
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use twin_core::error::{Error, Result};
use twin_core::topics::{Sink, TopicInfo, TypedMessage};

/// The endpoint version twin says in its handshake (the ROS-TCP-Endpoint release whose
/// protocol it speaks).
pub const ENDPOINT_VERSION: &str = "v0.7.0";

/// Largest destination and payload accepted, bytes.
const MAX_DESTINATION: u32 = 1024;
const MAX_PAYLOAD: u32 = 64 << 20;

struct Client {
    id: u64,
    queue: SyncSender<Vec<u8>>,
    subscriptions: Arc<Mutex<HashSet<String>>>,
}

#[derive(Default)]
struct State {
    /// Topic → type (`pkg/msg/Type`).
    topics: Vec<(String, String)>,
    clients: Vec<Client>,
    messages: Vec<ClientMessage>,
}

struct Shared {
    state: Mutex<State>,
    stop: AtomicBool,
    subscribed: AtomicU64,
    dropped: AtomicU64,
    next_client: AtomicU64,
}

/// The running endpoint. Dropping it stops accepting and closes the clients.
pub struct Server {
    shared: Arc<Shared>,
    addr: SocketAddr,
    listener: Option<std::thread::JoinHandle<()>>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// One frame: destination and payload, length-prefixed.
pub fn frame(destination: &str, payload: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(8 + destination.len() + payload.len());
    f.extend_from_slice(&(destination.len() as u32).to_le_bytes());
    f.extend_from_slice(destination.as_bytes());
    f.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    f.extend_from_slice(payload);
    f
}

fn command(name: &str, params: &Value) -> Vec<u8> {
    frame(name, params.to_string().as_bytes())
}

/// Unity's `pkg/Type` for `pkg/msg/Type`.
fn unity_type(type_name: &str) -> String {
    type_name.replace("/msg/", "/")
}

impl Server {
    /// Binds `addr` and starts accepting Unity clients.
    ///
    /// # Errors
    /// [`Error::Live`] when the address can't be bound.
    pub fn start(addr: SocketAddr) -> Result<Server> {
        let listener = TcpListener::bind(addr).map_err(|e| Error::Live {
            message: format!(
                "Unity endpoint: cannot listen on {addr}: {e} (port in use? give another with --unity PORT)"
            ),
        })?;
        let addr = listener.local_addr().map_err(|e| Error::Live { message: format!("Unity endpoint: {e}") })?;
        listener.set_nonblocking(true).map_err(|e| Error::Live { message: format!("Unity endpoint: {e}") })?;
        let shared = Arc::new(Shared {
            state: Mutex::default(),
            stop: AtomicBool::new(false),
            subscribed: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            next_client: AtomicU64::new(1),
        });
        let s = shared.clone();
        let handle = std::thread::Builder::new()
            .name("unity-accept".into())
            .spawn(move || {
                while !s.stop.load(Ordering::Relaxed) {
                    match listener.accept() {
                        Ok((stream, _)) => {
                            let s2 = s.clone();
                            let _ = std::thread::Builder::new()
                                .name("unity-client".into())
                                .spawn(move || serve(stream, &s2));
                        }
                        Err(_) => std::thread::sleep(Duration::from_millis(20)),
                    }
                }
            })
            .map_err(|e| Error::Live { message: format!("Unity endpoint: starting its thread: {e}") })?;
        Ok(Server { shared, addr, listener: Some(handle) })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Offers a topic (for `__subscribe` and `__topic_list`).
    pub fn add_topic(&self, topic: &str, type_name: &str) {
        let mut st = lock(&self.shared.state);
        if !st.topics.iter().any(|(t, _)| t == topic) {
            st.topics.push((topic.to_string(), type_name.to_string()));
        }
    }

    /// Whether a client subscribes to `topic`.
    pub fn is_subscribed(&self, topic: &str) -> bool {
        self.shared.subscribed.load(Ordering::Relaxed) > 0
            && lock(&self.shared.state).clients.iter().any(|c| lock(&c.subscriptions).contains(topic))
    }

    /// Sends a message (CDR) of `topic` to its subscribers; never blocks.
    pub fn publish(&self, topic: &str, cdr: &[u8]) {
        if self.shared.subscribed.load(Ordering::Relaxed) == 0 {
            return;
        }
        let st = lock(&self.shared.state);
        let mut f: Option<Vec<u8>> = None;
        for c in &st.clients {
            if lock(&c.subscriptions).contains(topic) {
                let bytes = f.get_or_insert_with(|| frame(topic, cdr)).clone();
                if let Err(TrySendError::Full(_)) = c.queue.try_send(bytes) {
                    self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// The messages Unity published since the last call.
    pub fn take_client_messages(&self) -> Vec<ClientMessage> {
        std::mem::take(&mut lock(&self.shared.state).messages)
    }

    /// Messages dropped for a full client queue.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.listener.take() {
            let _ = h.join();
        }
    }
}

/// Reads exactly `buf.len()` bytes, going on after read timeouts; `Ok(false)` when stopped or
/// the peer closed.
fn read_full(stream: &mut TcpStream, buf: &mut [u8], stop: &AtomicBool) -> std::io::Result<bool> {
    let mut got = 0;
    while got < buf.len() {
        if stop.load(Ordering::Relaxed) {
            return Ok(false);
        }
        match stream.read(&mut buf[got..]) {
            Ok(0) => return Ok(false),
            Ok(n) => got += n,
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(true)
}

fn read_u32(stream: &mut TcpStream, stop: &AtomicBool) -> std::io::Result<Option<u32>> {
    let mut b = [0u8; 4];
    Ok(read_full(stream, &mut b, stop)?.then(|| u32::from_le_bytes(b)))
}

fn serve(mut stream: TcpStream, shared: &Arc<Shared>) {
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_nodelay(true);
    let _ = stream.set_read_timeout(Some(Duration::from_millis(50)));
    let Ok(mut writer) = stream.try_clone() else { return };
    let (tx, rx) = sync_channel::<Vec<u8>>(4096);
    let id = shared.next_client.fetch_add(1, Ordering::Relaxed);
    let subscriptions: Arc<Mutex<HashSet<String>>> = Arc::default();
    // As the endpoint does: an empty message first, then the handshake.
    let _ = tx.try_send(frame("", &[]));
    let _ = tx.try_send(command(
        "__handshake",
        &json!({"version": ENDPOINT_VERSION, "metadata": json!({"protocol": "ROS2", "server": "twin"}).to_string()}),
    ));
    lock(&shared.state).clients.push(Client { id, queue: tx.clone(), subscriptions: subscriptions.clone() });
    let stop_writer = Arc::new(AtomicBool::new(false));
    let sw = stop_writer.clone();
    let writer_thread = std::thread::spawn(move || {
        while !sw.load(Ordering::Relaxed) {
            match rx.recv_timeout(Duration::from_millis(50)) {
                Ok(f) => {
                    if writer.write_all(&f).is_err() {
                        break;
                    }
                }
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                Err(_) => break,
            }
        }
    });
    let mut publishes: HashMap<String, String> = HashMap::new();
    let error = |text: String| {
        let _ = tx.try_send(command("__error", &json!({"text": text})));
    };
    // A frame: the destination, then the payload, each a u32 length and its bytes; `None` ends
    // the connection (closed, stopped, or a length over `max`, said to the client).
    // `what` names the field and `beyond` says what a longer one means.
    let field = |stream: &mut TcpStream, max: u32, what: &str, beyond: &str| -> Option<Vec<u8>> {
        let len = read_u32(stream, &shared.stop).ok()??;
        if len > max {
            error(format!("{what} of {len} bytes (at most {max}){beyond}"));
            return None;
        }
        let mut bytes = vec![0u8; len as usize];
        matches!(read_full(stream, &mut bytes, &shared.stop), Ok(true)).then_some(bytes)
    };
    while let Some(dest) = field(&mut stream, MAX_DESTINATION, "destination", ": not a ROS-TCP-Connector frame") {
        let Some(payload) = field(&mut stream, MAX_PAYLOAD, "payload", "") else { break };
        let dest = String::from_utf8_lossy(&dest).trim_end_matches('\0').to_string();
        if dest.is_empty() {
            continue; // keepalive
        }
        if let Some(cmd) = dest.strip_prefix("__") {
            // JSON, then one trailing byte.
            let text = String::from_utf8_lossy(&payload);
            let text = text.trim_end_matches(['\0', '\n', ' ']);
            let params: Value = serde_json::from_str(text)
                .or_else(|_| serde_json::from_str(&text[..text.len().saturating_sub(1)]))
                .unwrap_or(Value::Null);
            let field = |k: &str| params[k].as_str().unwrap_or("").to_string();
            match cmd {
                "subscribe" => {
                    let topic = field("topic");
                    let st = lock(&shared.state);
                    match st.topics.iter().find(|(t, _)| *t == topic) {
                        Some((_, ty)) if unity_type(ty) == unity_type(&field("message_name")) => {
                            if lock(&subscriptions).insert(topic) {
                                shared.subscribed.fetch_add(1, Ordering::Relaxed);
                            }
                        }
                        Some((_, ty)) => error(format!(
                            "__subscribe {topic}: the topic is {}, not {}",
                            unity_type(ty),
                            field("message_name")
                        )),
                        None => error(format!(
                            "__subscribe: no topic {topic:?}; twin's topics: {}",
                            st.topics.iter().map(|(t, _)| t.as_str()).collect::<Vec<_>>().join(", ")
                        )),
                    }
                }
                "publish" => {
                    publishes.insert(field("topic"), field("message_name"));
                }
                "topic_list" => {
                    let st = lock(&shared.state);
                    let topics: Vec<&str> = st.topics.iter().map(|(t, _)| t.as_str()).collect();
                    let types: Vec<String> = st.topics.iter().map(|(_, ty)| unity_type(ty)).collect();
                    let _ = tx.try_send(command("__topic_list", &json!({"topics": topics, "types": types})));
                }
                other => error(format!("twin's endpoint does not handle __{other} (services are not offered)")),
            }
            continue;
        }
        match publishes.get(&dest) {
            Some(ty) => lock(&shared.state).messages.push(ClientMessage {
                topic: dest,
                encoding: "cdr".into(),
                schema_name: ty.clone(),
                payload,
            }),
            None => error(format!("not registered to publish {dest:?}: send __publish first")),
        }
    }
    let removed = {
        let mut st = lock(&shared.state);
        st.clients.retain(|c| c.id != id);
        lock(&subscriptions).len() as u64
    };
    shared.subscribed.fetch_sub(removed, Ordering::Relaxed);
    stop_writer.store(true, Ordering::Relaxed);
    let _ = writer_thread.join();
}

/// The recording's sink for Unity: every topic is offered; a message is encoded only when a
/// client subscribes to its topic.
pub struct UnitySink {
    server: Arc<Server>,
    names: twin_core::topics::ById<String>,
    cdr: twin_core::log::cdr::CdrWriter,
}

impl UnitySink {
    /// A sink for `server`.
    pub fn new(server: Arc<Server>) -> UnitySink {
        UnitySink { server, names: Default::default(), cdr: twin_core::log::cdr::CdrWriter::new() }
    }
}

impl Sink for UnitySink {
    fn add_topic(&mut self, id: usize, topic: &TopicInfo) -> Result<bool> {
        self.server.add_topic(&topic.name, topic.type_name);
        self.names.set(id, topic.name.clone());
        Ok(true)
    }

    fn write(&mut self, id: usize, _topic: &TopicInfo, _log_time_nanos: u64, message: &TypedMessage<'_>) -> Result<()> {
        if let Some(name) = self.names.get(id)
            && self.server.is_subscribed(name)
        {
            let bytes = message.to_cdr(&mut self.cdr);
            self.server.publish(name, bytes);
        }
        Ok(())
    }
}
