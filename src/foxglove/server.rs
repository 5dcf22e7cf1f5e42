//! The SDK's WebSocket server on the address asked, with every bus's
//! channels advertised as a recording declares them
//! ([`record::channels::specs`](crate::record::channels::specs), JSON side
//! channels as in a default recording), and a listener that counts clients.
//!
//! The server advertises no capability: a client can subscribe, and
//! nothing else (no publishing, no services, no parameters). The live view
//! is read only; it cannot move a joint.

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

use ::foxglove::websocket::{ServerListener, ShutdownHandle};
use ::foxglove::{Context, FoxgloveError, RawChannel, Schema, WebSocketServerHandle};

use super::LiveError;
use crate::control::foxglove_stats::FoxgloveStats;
use crate::record::channels::{specs, ChannelSpec, SideEncoding, Topic};

/// How many messages each client's queue holds (the SDK's message
/// backlog; the SDK's default, said here on purpose). Logging a message
/// never waits: when a client's queue is full (it reads slower than the
/// buses talk, or not at all), the SDK drops that client's oldest queued
/// messages to make room (up to 10 for one new message, else the new one
/// is dropped), so a slow client sees gaps and slows nobody. 1024 is
/// about 0.4 s of a saturated 500000-baud line's frames, or 20 s of one
/// bus's joint states alone. The same bound holds the client's protocol
/// messages (advertisements, status); a client that lets those fill is
/// disconnected by the SDK.
const MESSAGE_BACKLOG: usize = 1024;

/// The live channels of one bus, by topic (cheap to clone: `Arc`s).
#[derive(Debug, Clone)]
pub(super) struct BusChannels {
    channels: Vec<(Topic, Arc<RawChannel>)>,
}

impl BusChannels {
    pub(super) fn get(&self, topic: Topic) -> Option<&Arc<RawChannel>> {
        self.channels
            .iter()
            .find(|(t, _)| *t == topic)
            .map(|(_, c)| c)
    }
}

/// The server, listening, and the channels it advertises.
pub(super) struct LiveServer {
    handle: WebSocketServerHandle,
    /// The channels' context (the SDK's registry of channels and sinks);
    /// held so that the channels stay advertised.
    _context: Arc<Context>,
    channels: Vec<(String, BusChannels)>,
    addr: SocketAddr,
}

impl LiveServer {
    /// Creates the channels of `buses` and starts the server on `addr`
    /// (on the daemon's runtime: the SDK takes the current one).
    pub(super) async fn bind(
        addr: SocketAddr,
        buses: &[String],
        stats: Arc<FoxgloveStats>,
    ) -> Result<Self, LiveError> {
        let context = Context::new();
        let mut channels = Vec::with_capacity(buses.len());
        for bus in buses {
            let made = bus_channels(&context, bus).map_err(|e| sdk_error(addr, e))?;
            channels.push((bus.clone(), made));
        }
        let handle = context
            .websocket_server()
            .name(concat!("jointd ", env!("CARGO_PKG_VERSION")))
            .bind(host(addr.ip()), addr.port())
            .message_backlog_size(MESSAGE_BACKLOG)
            .listener(Arc::new(Clients(stats)))
            .start()
            .await
            .map_err(|e| sdk_error(addr, e))?;
        let addr = SocketAddr::new(addr.ip(), handle.port());
        Ok(Self {
            handle,
            _context: context,
            channels,
            addr,
        })
    }

    /// Where it listens (the port the system chose, when asked for 0).
    pub(super) fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The channels of bus `name`.
    pub(super) fn channels(&self, name: &str) -> Option<BusChannels> {
        self.channels
            .iter()
            .find(|(bus, _)| bus == name)
            .map(|(_, c)| c.clone())
    }

    /// Stops accepting and closes every client's connection; the handle
    /// waits for the client tasks to end.
    pub(super) fn stop(self) -> ShutdownHandle {
        self.handle.stop()
    }
}

/// The four channels of `bus`, as a default recording declares them.
fn bus_channels(context: &Arc<Context>, bus: &str) -> Result<BusChannels, FoxgloveError> {
    let mut channels = Vec::with_capacity(Topic::ALL.len());
    for spec in specs(bus, SideEncoding::Json) {
        channels.push((spec.topic, channel(context, spec)?));
    }
    Ok(BusChannels { channels })
}

fn channel(context: &Arc<Context>, spec: ChannelSpec) -> Result<Arc<RawChannel>, FoxgloveError> {
    let schema = Schema::new(
        spec.schema_name,
        spec.schema_encoding,
        spec.schema.into_bytes(),
    );
    context
        .channel_builder(spec.name)
        .message_encoding(spec.encoding)
        .schema(schema)
        .metadata(spec.metadata)
        .build_raw()
}

/// The host as the SDK binds it (`host:port`): an IPv6 address in brackets.
fn host(ip: IpAddr) -> String {
    match ip {
        IpAddr::V4(v4) => v4.to_string(),
        IpAddr::V6(v6) => format!("[{v6}]"),
    }
}

fn sdk_error(addr: SocketAddr, e: FoxgloveError) -> LiveError {
    match e {
        FoxgloveError::Bind(source) => LiveError::Bind { addr, source },
        other => LiveError::Sdk(other.to_string()),
    }
}

/// Counts the clients connected, for `/metrics`.
struct Clients(Arc<FoxgloveStats>);

impl ServerListener for Clients {
    fn on_client_connect(&self) {
        self.0.client_connected();
    }

    fn on_client_disconnect(&self) {
        self.0.client_disconnected();
    }
}
