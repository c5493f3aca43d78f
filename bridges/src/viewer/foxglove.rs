//! A Foxglove WebSocket server (the `foxglove.websocket.v1` protocol, also accepted under its
//! SDK name `foxglove.sdk.v1`): Foxglove, Lichtblick and other clients see the twin live,
//! without ROS.
//!
//! Data flow: [`Server::start`] binds a TCP listener (loopback by default) and accepts clients
//! on a thread; each client has its own thread that completes the WebSocket handshake, sends
//! `serverInfo`, the channels (`advertise`) and the services (`advertiseServices`), then reads
//! the client's requests (subscribe, unsubscribe, client advertise, fetchAsset, service calls,
//! client messages) and writes what the publisher queued for it. The publisher side is
//! [`Server::publish`] (called by [`FoxgloveSink`], the recording's [`Sink`], or by a log
//! player): it writes a message only for clients subscribed to its channel, into a bounded
//! per-client queue that never blocks the simulation (a full queue drops, counted). Channels
//! are the topic table's: CDR with the `ros2msg` schema twin writes into MCAP.
//!
//! Services (`/twin/pause`, `/twin/resume`, `/twin/step`, `/twin/reset`; JSON) and client
//! messages are queued for the simulation side ([`Server::take_calls`],
//! [`Server::take_client_messages`]): [`SimHook`] answers them between steps, paces the run
//! and blocks while paused.

use serde_json::{Value, json};
use std::collections::HashMap;
use std::io::ErrorKind;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;
use twin_core::error::{Error, Result};
use twin_core::topics::{Durability, Sink, TopicInfo, TypedMessage};

/// Subprotocols accepted, in order of preference (the spec's name, then the SDK's).
pub const SUBPROTOCOLS: [&str; 2] = ["foxglove.websocket.v1", "foxglove.sdk.v1"];

/// Messages queued per client before new ones are dropped.
const QUEUE: usize = 4096;

/// How long a client thread waits for a request before it writes what was queued: the
/// messages of that span go out in one batch (one flush, one wake-up of the client), so a
/// client subscribed to everything costs the simulation little (benches/foxglove_stream.sh).
const POLL: Duration = Duration::from_millis(10);

/// How long the last messages may take to reach a client when the server stops (a client
/// that reads no more is given up after about this).
const DRAIN: Duration = Duration::from_secs(1);

/// Options of the server.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct FoxgloveOptions {
    /// Address to listen on (default: 127.0.0.1:8765, loopback only).
    #[default(SocketAddr::from(([127, 0, 0, 1], 8765)))]
    pub addr: SocketAddr,
    /// Server name shown by clients (default: "twin").
    #[default("twin")]
    pub name: String,
    /// The robot file, for `package://` assets (its packages are found as the converter finds
    /// its meshes) (default: none: no assets).
    pub robot_file: Option<PathBuf>,
    /// Offer the pause/resume/step/reset services (default: true; false for a log player
    /// that cannot reset).
    #[default(true)]
    pub services: bool,
}

/// A channel the server offers.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Channel id.
    pub id: u32,
    /// Topic.
    pub topic: String,
    /// Message encoding (`cdr`).
    pub encoding: String,
    /// Schema name (`sensor_msgs/msg/JointState`).
    pub schema_name: String,
    /// Schema text (`ros2msg`).
    pub schema: String,
    /// Schema encoding (`ros2msg`).
    pub schema_encoding: String,
    /// Latched: the last message goes to each new subscriber.
    pub latched: bool,
}

/// A service of the server: id, name, what it does.
pub const SERVICES: [(u32, &str, &str); 4] = [
    (1, "/twin/pause", "pause the simulation"),
    (2, "/twin/resume", "resume real-time stepping"),
    (3, "/twin/step", "while paused, step {\"steps\": N} physics steps (default 1)"),
    (4, "/twin/reset", "put the state the run started from back"),
];

/// A service call from a client, waiting for the simulation side.
#[derive(Debug)]
pub struct Call {
    /// Service id (see [`SERVICES`]).
    pub service: u32,
    /// The client's call id.
    pub call_id: u32,
    /// Request encoding (`json`).
    pub encoding: String,
    /// Request payload.
    pub payload: Vec<u8>,
    reply: SyncSender<Vec<u8>>,
}

impl Call {
    /// Sends the response (JSON) to the caller.
    pub fn answer(&self, response: &Value) {
        let mut frame = vec![0x03];
        frame.extend_from_slice(&self.service.to_le_bytes());
        frame.extend_from_slice(&self.call_id.to_le_bytes());
        frame.extend_from_slice(&(self.encoding.len() as u32).to_le_bytes());
        frame.extend_from_slice(self.encoding.as_bytes());
        frame.extend_from_slice(response.to_string().as_bytes());
        let _ = self.reply.try_send(frame);
    }
}

/// A message a client published on one of its channels.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientMessage {
    /// The client channel's topic.
    pub topic: String,
    /// Its encoding (`cdr` or `json`).
    pub encoding: String,
    /// Its schema name.
    pub schema_name: String,
    /// The payload.
    pub payload: Vec<u8>,
}

struct Client {
    id: u64,
    queue: SyncSender<Vec<u8>>,
    /// Channel id → subscription id.
    subscriptions: Arc<Mutex<HashMap<u32, u32>>>,
}

#[derive(Default)]
struct State {
    channels: Vec<Channel>,
    /// Last message of latched channels (channel id → (time, payload)).
    latched: HashMap<u32, (u64, Vec<u8>)>,
    clients: Vec<Client>,
    calls: Vec<Call>,
    client_messages: Vec<ClientMessage>,
}

struct Shared {
    options: FoxgloveOptions,
    state: Mutex<State>,
    stop: AtomicBool,
    /// Subscriptions over all clients (a cheap "anyone listening?" before encoding).
    subscribed: AtomicU64,
    dropped: AtomicU64,
    next_client: AtomicU64,
    clients_seen: AtomicU64,
}

/// The running server. Dropping it stops the listener and closes the clients.
pub struct Server {
    shared: Arc<Shared>,
    addr: SocketAddr,
    listener: Option<JoinHandle<()>>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Server {
    /// Binds `options.addr` and starts accepting clients.
    ///
    /// # Errors
    /// [`Error::Live`] when the address can't be bound (in use, not this machine's).
    pub fn start(options: FoxgloveOptions) -> Result<Server> {
        let listener = TcpListener::bind(options.addr).map_err(|e| Error::Live {
            message: format!(
                "Foxglove server: cannot listen on {}: {e} (another server on that port? give another with \
                 --foxglove PORT)",
                options.addr
            ),
        })?;
        let addr = listener.local_addr().map_err(|e| Error::Live { message: format!("Foxglove server: {e}") })?;
        listener
            .set_nonblocking(true)
            .map_err(|e| Error::Live { message: format!("Foxglove server: non-blocking listener: {e}") })?;
        let shared = Arc::new(Shared {
            options,
            state: Mutex::default(),
            stop: AtomicBool::new(false),
            subscribed: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            next_client: AtomicU64::new(1),
            clients_seen: AtomicU64::new(0),
        });
        let s = shared.clone();
        let listener = std::thread::Builder::new()
            .name("foxglove-accept".into())
            .spawn(move || accept_loop(&listener, &s))
            .map_err(|e| Error::Live { message: format!("Foxglove server: starting its thread: {e}") })?;
        Ok(Server { shared, addr, listener: Some(listener) })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Adds a channel (told to connected clients at once); returns its id.
    pub fn add_channel(&self, topic: &str, schema_name: &str, schema: &str, latched: bool) -> u32 {
        let mut st = lock(&self.shared.state);
        if let Some(c) = st.channels.iter().find(|c| c.topic == topic) {
            return c.id;
        }
        let id = st.channels.len() as u32 + 1;
        let channel = Channel {
            id,
            topic: topic.into(),
            encoding: "cdr".into(),
            schema_name: schema_name.into(),
            schema: schema.into(),
            schema_encoding: "ros2msg".into(),
            latched,
        };
        let frame = text_frame(&advertise(std::slice::from_ref(&channel)));
        for c in &st.clients {
            let _ = c.queue.try_send(frame.clone());
        }
        st.channels.push(channel);
        id
    }

    /// Whether a client subscribes to channel `id`.
    pub fn is_subscribed(&self, id: u32) -> bool {
        if self.shared.subscribed.load(Ordering::Relaxed) == 0 {
            return false;
        }
        lock(&self.shared.state).clients.iter().any(|c| lock(&c.subscriptions).contains_key(&id))
    }

    /// Whether any client is connected.
    pub fn has_clients(&self) -> bool {
        !lock(&self.shared.state).clients.is_empty()
    }

    /// Sends a message of channel `id`, stamped `time_nanos`, to its subscribers (kept for new
    /// subscribers when latched). Never blocks: a client whose queue is full misses it.
    pub fn publish(&self, id: u32, time_nanos: u64, payload: &[u8]) {
        let mut st = lock(&self.shared.state);
        if st.channels.get(id as usize - 1).is_some_and(|c| c.latched) {
            st.latched.insert(id, (time_nanos, payload.to_vec()));
        }
        if self.shared.subscribed.load(Ordering::Relaxed) == 0 {
            return;
        }
        for c in &st.clients {
            let sub = lock(&c.subscriptions).get(&id).copied();
            if let Some(sub) = sub {
                let frame = message_data(sub, time_nanos, payload);
                if let Err(TrySendError::Full(_)) = c.queue.try_send(frame) {
                    self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// Tells clients the server time (the `time` capability).
    pub fn broadcast_time(&self, time_nanos: u64) {
        let st = lock(&self.shared.state);
        if st.clients.is_empty() {
            return;
        }
        let mut frame = vec![0x02];
        frame.extend_from_slice(&time_nanos.to_le_bytes());
        for c in &st.clients {
            let _ = c.queue.try_send(frame.clone());
        }
    }

    /// Sends a status message to every client (0 info, 1 warning, 2 error).
    pub fn status(&self, level: u8, message: &str) {
        let text = json!({"op": "status", "level": level, "message": message}).to_string();
        for c in &lock(&self.shared.state).clients {
            let _ = c.queue.try_send(text_frame(&text));
        }
    }

    /// The service calls waiting.
    pub fn take_calls(&self) -> Vec<Call> {
        std::mem::take(&mut lock(&self.shared.state).calls)
    }

    /// The messages clients published since the last call.
    pub fn take_client_messages(&self) -> Vec<ClientMessage> {
        std::mem::take(&mut lock(&self.shared.state).client_messages)
    }

    /// Messages dropped because a client's queue was full.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Clients that connected so far.
    pub fn clients_seen(&self) -> u64 {
        self.shared.clients_seen.load(Ordering::Relaxed)
    }

    /// Waits up to `timeout` for a client to subscribe to something.
    pub fn wait_for_subscriber(&self, timeout: Duration, stop: &AtomicBool) -> bool {
        let deadline = std::time::Instant::now() + timeout;
        while std::time::Instant::now() < deadline && !stop.load(Ordering::Relaxed) {
            if self.shared.subscribed.load(Ordering::Relaxed) > 0 {
                return true;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        self.shared.subscribed.load(Ordering::Relaxed) > 0
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

/// A text frame marker: queued frames are bytes; text ones end with a NUL the writer strips.
fn text_frame(text: &str) -> Vec<u8> {
    let mut v = text.as_bytes().to_vec();
    v.push(0);
    v
}

fn message_data(sub: u32, time_nanos: u64, payload: &[u8]) -> Vec<u8> {
    let mut frame = Vec::with_capacity(13 + payload.len());
    frame.push(0x01);
    frame.extend_from_slice(&sub.to_le_bytes());
    frame.extend_from_slice(&time_nanos.to_le_bytes());
    frame.extend_from_slice(payload);
    frame
}

fn advertise(channels: &[Channel]) -> String {
    let list: Vec<Value> = channels
        .iter()
        .map(|c| {
            json!({"id": c.id, "topic": c.topic, "encoding": c.encoding, "schemaName": c.schema_name,
                   "schema": c.schema, "schemaEncoding": c.schema_encoding})
        })
        .collect();
    json!({"op": "advertise", "channels": list}).to_string()
}

fn accept_loop(listener: &TcpListener, shared: &Arc<Shared>) {
    let mut threads = Vec::new();
    while !shared.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                let s = shared.clone();
                if let Ok(h) =
                    std::thread::Builder::new().name("foxglove-client".into()).spawn(move || serve(stream, &s))
                {
                    threads.push(h);
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => std::thread::sleep(Duration::from_millis(20)),
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    for h in threads {
        let _ = h.join();
    }
}

/// Picks the subprotocol from the client's offer.
fn pick_subprotocol(offered: &str) -> Option<&'static str> {
    let offered: Vec<&str> = offered.split(',').map(str::trim).collect();
    SUBPROTOCOLS.into_iter().find(|p| offered.contains(p))
}

fn serve(stream: TcpStream, shared: &Arc<Shared>) {
    use tungstenite::handshake::server::{ErrorResponse, Request, Response};
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_nodelay(true);
    // The handshake is bounded.
    let _ = stream.set_read_timeout(Some(Duration::from_secs(5)));
    let mut chosen = "";
    // tungstenite's callback type returns its (large) error response by value.
    #[allow(clippy::result_large_err)]
    let callback = |req: &Request, mut res: Response| -> std::result::Result<Response, ErrorResponse> {
        let offered = req
            .headers()
            .get_all("sec-websocket-protocol")
            .iter()
            .filter_map(|h| h.to_str().ok())
            .collect::<Vec<_>>()
            .join(",");
        match pick_subprotocol(&offered) {
            Some(p) => {
                chosen = p;
                res.headers_mut().insert("sec-websocket-protocol", tungstenite::http::HeaderValue::from_static(p));
                Ok(res)
            }
            None => {
                let mut err = ErrorResponse::new(Some(format!(
                    "twin's Foxglove server speaks the subprotocols {}; the client offered {offered:?}",
                    SUBPROTOCOLS.join(", ")
                )));
                *err.status_mut() = tungstenite::http::StatusCode::BAD_REQUEST;
                Err(err)
            }
        }
    };
    let Ok(mut ws) = tungstenite::accept_hdr(stream, callback) else { return };
    let _ = chosen;
    let _ = ws.get_ref().set_read_timeout(Some(POLL));
    let (tx, rx): (SyncSender<Vec<u8>>, Receiver<Vec<u8>>) = sync_channel(QUEUE);
    let id = shared.next_client.fetch_add(1, Ordering::Relaxed);
    shared.clients_seen.fetch_add(1, Ordering::Relaxed);
    let subscriptions: Arc<Mutex<HashMap<u32, u32>>> = Arc::default();
    // Hello: serverInfo, channels, services.
    {
        let mut st = lock(&shared.state);
        let mut capabilities = vec!["time", "clientPublish", "assets"];
        if shared.options.services {
            capabilities.push("services");
        }
        let info = json!({"op": "serverInfo", "name": shared.options.name, "capabilities": capabilities,
            "supportedEncodings": ["cdr", "json"], "metadata": {"twin": env!("CARGO_PKG_VERSION")},
            "sessionId": format!("{}", std::process::id())});
        let _ = tx.try_send(text_frame(&info.to_string()));
        let _ = tx.try_send(text_frame(&advertise(&st.channels)));
        if shared.options.services {
            let services: Vec<Value> = SERVICES
                .iter()
                .map(|(id, name, what)| {
                    json!({"id": id, "name": name, "type": "twin/srv/Control",
                        "requestSchema": format!("{{\"description\": \"{what}\", \"type\": \"object\"}}"),
                        "responseSchema": "{\"type\": \"object\"}",
                        "request": {"encoding": "json", "schemaName": "twin/srv/Control_Request", "schemaEncoding": "jsonschema", "schema": "{\"type\": \"object\"}"},
                        "response": {"encoding": "json", "schemaName": "twin/srv/Control_Response", "schemaEncoding": "jsonschema", "schema": "{\"type\": \"object\"}"}})
                })
                .collect();
            let _ = tx.try_send(text_frame(&json!({"op": "advertiseServices", "services": services}).to_string()));
        }
        st.clients.push(Client { id, queue: tx.clone(), subscriptions: subscriptions.clone() });
    }
    let mut client_channels: HashMap<u32, (String, String, String)> = HashMap::new();
    let assets = shared.options.robot_file.as_ref().map(|f| twin_core::convert::mesh::search_paths(f, &[]));
    'session: while !shared.stop.load(Ordering::Relaxed) {
        // Write what was queued.
        let mut wrote = false;
        while let Ok(frame) = rx.try_recv() {
            if ws.write(ws_message(frame)).is_err() {
                break 'session;
            }
            wrote = true;
        }
        if wrote && ws.flush().is_err() {
            break;
        }
        match ws.read() {
            Ok(tungstenite::Message::Text(t)) => {
                let reply = handle_json(t.as_str(), shared, &subscriptions, &mut client_channels, assets.as_ref(), &tx);
                for r in reply {
                    let _ = tx.try_send(r);
                }
            }
            Ok(tungstenite::Message::Binary(b)) => handle_binary(&b, shared, &client_channels, &tx),
            Ok(tungstenite::Message::Close(_)) => break,
            Ok(_) => {}
            Err(tungstenite::Error::Io(e)) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => break,
        }
    }
    let removed = {
        let mut st = lock(&shared.state);
        st.clients.retain(|c| c.id != id);
        lock(&subscriptions).len() as u64
    };
    shared.subscribed.fetch_sub(removed, Ordering::Relaxed);
    // The run ended: what it queued still reaches the client (bounded by DRAIN).
    if shared.stop.load(Ordering::Relaxed) {
        let _ = ws.get_ref().set_write_timeout(Some(DRAIN));
        let deadline = std::time::Instant::now() + DRAIN;
        while let Ok(frame) = rx.try_recv() {
            if std::time::Instant::now() > deadline || ws.write(ws_message(frame)).is_err() {
                break;
            }
        }
        let _ = ws.flush();
    }
    let _ = ws.close(None);
    let _ = ws.flush();
}

/// A queued frame as a WebSocket message (text frames end with the NUL marker).
fn ws_message(frame: Vec<u8>) -> tungstenite::Message {
    match frame.last() {
        Some(0) if frame.first() == Some(&b'{') => {
            tungstenite::Message::text(String::from_utf8_lossy(&frame[..frame.len() - 1]).into_owned())
        }
        _ => tungstenite::Message::binary(frame),
    }
}

fn status_frame(level: u8, message: &str) -> Vec<u8> {
    text_frame(&json!({"op": "status", "level": level, "message": message}).to_string())
}

fn handle_json(
    text: &str,
    shared: &Arc<Shared>,
    subscriptions: &Arc<Mutex<HashMap<u32, u32>>>,
    client_channels: &mut HashMap<u32, (String, String, String)>,
    assets: Option<&(PathBuf, Vec<PathBuf>)>,
    tx: &SyncSender<Vec<u8>>,
) -> Vec<Vec<u8>> {
    let Ok(v) = serde_json::from_str::<Value>(text) else {
        return vec![status_frame(2, "request is not JSON")];
    };
    let mut out = Vec::new();
    let as_u32 = |v: &Value| v.as_u64().and_then(|x| u32::try_from(x).ok());
    match v["op"].as_str().unwrap_or("") {
        "subscribe" => {
            let st = lock(&shared.state);
            for s in v["subscriptions"].as_array().into_iter().flatten() {
                let (Some(sub), Some(chan)) = (as_u32(&s["id"]), as_u32(&s["channelId"])) else { continue };
                if !st.channels.iter().any(|c| c.id == chan) {
                    out.push(status_frame(1, &format!("subscribe: no channel {chan}")));
                    continue;
                }
                if lock(subscriptions).insert(chan, sub).is_none() {
                    shared.subscribed.fetch_add(1, Ordering::Relaxed);
                }
                if let Some((t, payload)) = st.latched.get(&chan) {
                    out.push(message_data(sub, *t, payload));
                }
            }
        }
        "unsubscribe" => {
            let ids: Vec<u32> = v["subscriptionIds"].as_array().into_iter().flatten().filter_map(as_u32).collect();
            let mut subs = lock(subscriptions);
            let before = subs.len();
            subs.retain(|_, sub| !ids.contains(sub));
            shared.subscribed.fetch_sub((before - subs.len()) as u64, Ordering::Relaxed);
        }
        "advertise" => {
            for c in v["channels"].as_array().into_iter().flatten() {
                let Some(id) = as_u32(&c["id"]) else { continue };
                let field = |k: &str| c[k].as_str().unwrap_or("").to_string();
                client_channels.insert(id, (field("topic"), field("encoding"), field("schemaName")));
            }
        }
        "unadvertise" => {
            for id in v["channelIds"].as_array().into_iter().flatten().filter_map(as_u32) {
                client_channels.remove(&id);
            }
        }
        "fetchAsset" => {
            let request = as_u32(&v["requestId"]).unwrap_or(0);
            let uri = v["uri"].as_str().unwrap_or("");
            out.push(fetch_asset(request, uri, assets));
        }
        other => out.push(status_frame(1, &format!("twin's Foxglove server does not handle op {other:?}"))),
    }
    let _ = tx;
    out
}

/// The file of a `package://` (or `file://` under a package) URI, as the converter finds meshes.
fn fetch_asset(request: u32, uri: &str, assets: Option<&(PathBuf, Vec<PathBuf>)>) -> Vec<u8> {
    let result: std::result::Result<Vec<u8>, String> = (|| {
        let (dir, search) = assets.ok_or("this server has no robot file to serve assets from")?;
        if !uri.starts_with("package://") {
            return Err(format!("only package:// URIs are served, not {uri:?}"));
        }
        if uri.split('/').any(|part| part == "..") {
            return Err(format!("{uri:?} climbs out of its package (`..`)"));
        }
        let path = twin_core::convert::mesh::resolve(uri, dir, search)?;
        std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))
    })();
    let mut frame = vec![0x04];
    frame.extend_from_slice(&request.to_le_bytes());
    match result {
        Ok(data) => {
            frame.push(0);
            frame.extend_from_slice(&0u32.to_le_bytes());
            frame.extend_from_slice(&data);
        }
        Err(e) => {
            frame.push(1);
            frame.extend_from_slice(&(e.len() as u32).to_le_bytes());
            frame.extend_from_slice(e.as_bytes());
        }
    }
    frame
}

fn handle_binary(
    b: &[u8],
    shared: &Arc<Shared>,
    client_channels: &HashMap<u32, (String, String, String)>,
    tx: &SyncSender<Vec<u8>>,
) {
    let u32_at = |i: usize| b.get(i..i + 4).map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]));
    match b.first() {
        Some(0x01) => {
            let Some(chan) = u32_at(1) else { return };
            match client_channels.get(&chan) {
                Some((topic, encoding, schema_name)) => lock(&shared.state).client_messages.push(ClientMessage {
                    topic: topic.clone(),
                    encoding: encoding.clone(),
                    schema_name: schema_name.clone(),
                    payload: b[5..].to_vec(),
                }),
                None => {
                    let _ = tx.try_send(status_frame(1, &format!("message on unadvertised client channel {chan}")));
                }
            }
        }
        Some(0x02) => {
            let (Some(service), Some(call_id), Some(len)) = (u32_at(1), u32_at(5), u32_at(9)) else { return };
            let end = 13 + len as usize;
            let Some(enc) = b.get(13..end) else { return };
            let call = Call {
                service,
                call_id,
                encoding: String::from_utf8_lossy(enc).into_owned(),
                payload: b[end..].to_vec(),
                reply: tx.clone(),
            };
            if shared.options.services && SERVICES.iter().any(|s| s.0 == service) {
                lock(&shared.state).calls.push(call);
            } else {
                call.answer(&json!({"ok": false, "message": format!("no service {service}")}));
            }
        }
        _ => {
            let _ = tx.try_send(status_frame(1, "unknown binary opcode"));
        }
    }
}

/// The recording's [`Sink`] that streams to a [`Server`]: each topic becomes a channel; a
/// message is encoded only when a client subscribes to its topic.
pub struct FoxgloveSink {
    server: Arc<Server>,
    /// Channel of each topic id, and whether it is latched.
    by_id: twin_core::topics::ById<(u32, bool)>,
    cdr: twin_core::log::cdr::CdrWriter,
    last_time: u64,
}

impl FoxgloveSink {
    /// A sink streaming to `server`.
    pub fn new(server: Arc<Server>) -> FoxgloveSink {
        FoxgloveSink {
            server,
            by_id: Default::default(),
            cdr: twin_core::log::cdr::CdrWriter::new(),
            last_time: u64::MAX,
        }
    }
}

impl Sink for FoxgloveSink {
    fn add_topic(&mut self, id: usize, topic: &TopicInfo) -> Result<bool> {
        let Some(schema) = twin_core::log::typed::schema_text(topic.type_name) else { return Ok(false) };
        let latched = topic.qos.durability == Durability::TransientLocal;
        let chan = self.server.add_channel(&topic.name, topic.type_name, &schema, latched);
        self.by_id.set(id, (chan, latched));
        Ok(true)
    }

    fn write(&mut self, id: usize, _topic: &TopicInfo, log_time_nanos: u64, message: &TypedMessage<'_>) -> Result<()> {
        if log_time_nanos != self.last_time {
            self.last_time = log_time_nanos;
            self.server.broadcast_time(log_time_nanos);
        }
        // Encoded only for a subscriber, or to keep a latched topic's last message.
        if let Some((chan, latched)) = self.by_id.get(id)
            && (*latched || self.server.is_subscribed(*chan))
        {
            let bytes = message.to_cdr(&mut self.cdr);
            self.server.publish(*chan, log_time_nanos, bytes);
        }
        Ok(())
    }
}
