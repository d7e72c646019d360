use std::cell::{Cell, RefCell};
use std::time::{Duration, Instant};

use iceoryx2::active_request::ActiveRequest;
use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::ServiceName;
use iceoryx2::service::port_factory::request_response::PortFactory;

use super::error::{ice, IpcError};
use super::ports::open_event;
use super::retry::retry_creation;
use super::topics::MAX_NODES;
use super::{Ipc, IpcConfig, IpcNode};
use crate::messages::{ControlRequest, ControlResponse, RequestKind, ResponseCode};
use crate::validate::Validate;

/// Service name leaf of the control service (`<ns>/control`, event `<ns>/control/event`).
pub const CONTROL_LEAF: &str = "control";

/// Most control clients (thrusterctl instances, tests) at a time.
const MAX_CLIENTS: usize = 8;
/// Requests one client may have outstanding.
const MAX_ACTIVE_REQUESTS_PER_CLIENT: usize = 4;
/// How often [`ControlClient::call`] polls for the response. Control is operator-paced,
/// so a fraction of a millisecond of extra latency does not matter.
const RESPONSE_POLL: Duration = Duration::from_micros(200);

type ControlFactory = PortFactory<Ipc, ControlRequest, (), ControlResponse, ()>;

fn open_control(node: &IpcNode, ipc: &IpcConfig) -> Result<(String, ControlFactory), IpcError> {
    let name = ipc.service_name(CONTROL_LEAF);
    let service_name = ServiceName::new(&name).map_err(ice("make service name", &name))?;
    let factory = retry_creation(|| {
        node.service_builder(&service_name)
            .request_response::<ControlRequest, ControlResponse>()
            // One daemon per namespace: a second server fails to create, which catches two
            // daemons started on the same vehicle.
            .max_servers(1)
            .max_clients(MAX_CLIENTS)
            .max_active_requests_per_client(MAX_ACTIVE_REQUESTS_PER_CLIENT)
            .max_response_buffer_size(1)
            .max_nodes(MAX_NODES)
            .open_or_create()
    })
    .map_err(ice("open or create request-response service", &name))?;
    Ok((name, factory))
}

/// Outcome of one [`ControlServer::serve`] call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServeCount {
    /// Valid requests passed to the handler and answered.
    pub answered: usize,
    /// Requests that failed validation, answered with `InvalidRequest` without calling
    /// the handler.
    pub invalid: usize,
}

/// A handler's answer to one request (see [`ControlServer::serve_deferring`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reply {
    /// Answer now.
    Now(ControlResponse),
    /// Answer later, with [`ControlServer::answer`] and this token (the handler's own
    /// number for the operation): the request is kept open meanwhile.
    Later(u64),
}

type Active = ActiveRequest<Ipc, ControlRequest, (), ControlResponse, ()>;

/// The daemon's end of the control service: server plus the listener that client
/// requests notify. Not `Send`.
#[derive(Debug)]
pub struct ControlServer {
    server: Server<Ipc, ControlRequest, (), ControlResponse, ()>,
    listener: Listener<Ipc>,
    service: String,
    /// Requests answered later, by token: an operation that must not block the caller's loop
    /// (a model file read on another thread) answers when it is done.
    deferred: RefCell<Vec<(u64, u64, Active)>>,
}

impl ControlServer {
    /// Opens or creates the control service and creates the server (fails if another
    /// server exists in the namespace).
    pub fn create(node: &IpcNode, ipc: &IpcConfig) -> Result<Self, IpcError> {
        let (service, factory) = open_control(node, ipc)?;
        let server = factory
            .server_builder()
            .create()
            .map_err(ice("create server", &service))?;
        let listener = open_event(node, &service)?
            .listener_builder()
            .create()
            .map_err(ice("create listener", &service))?;
        Ok(Self {
            server,
            listener,
            service,
            deferred: RefCell::new(Vec::new()),
        })
    }

    /// The listener to attach to a wait set; clients notify it after each request.
    pub fn listener(&self) -> &Listener<Ipc> {
        &self.listener
    }

    /// Consumes pending notifications without blocking.
    pub fn drain_events(&self) -> Result<u64, IpcError> {
        self.listener
            .try_wait(|_| {})
            .map_err(ice("drain listener", &self.service))
    }

    /// Answers every pending request. Valid requests go to `handler` with their decoded
    /// kind; invalid ones are answered with [`ResponseCode::InvalidRequest`] and the
    /// reason, so garbage never reaches the daemon's logic. The response's `seq` is set
    /// to the request's.
    pub fn serve<F>(&self, mut handler: F) -> Result<ServeCount, IpcError>
    where
        F: FnMut(RequestKind, &ControlRequest) -> ControlResponse,
    {
        self.serve_deferring(|kind, request| Reply::Now(handler(kind, request)))
    }

    /// As [`ControlServer::serve`], but the handler may keep a request open
    /// ([`Reply::Later`]) and answer it with [`ControlServer::answer`] in a later round; the
    /// client waits for it up to its own timeout.
    pub fn serve_deferring<F>(&self, mut handler: F) -> Result<ServeCount, IpcError>
    where
        F: FnMut(RequestKind, &ControlRequest) -> Reply,
    {
        let mut count = ServeCount::default();
        while let Some(active) = self
            .server
            .receive()
            .map_err(ice("receive request", &self.service))?
        {
            let request = *active.payload();
            let response = match decode(&request) {
                Ok(kind) => {
                    count.answered += 1;
                    match handler(kind, &request) {
                        Reply::Now(response) => response,
                        Reply::Later(token) => {
                            self.deferred
                                .borrow_mut()
                                .push((token, request.seq, active));
                            continue;
                        }
                    }
                }
                Err(reason) => {
                    count.invalid += 1;
                    ControlResponse::new(ResponseCode::InvalidRequest, &reason)
                }
            };
            self.send(active, request.seq, response);
        }
        Ok(count)
    }

    /// Answers every request kept open with `token`; false when there was none.
    pub fn answer(&self, token: u64, response: ControlResponse) -> bool {
        let mut answered = false;
        let mut deferred = self.deferred.borrow_mut();
        while let Some(i) = deferred.iter().position(|(t, _, _)| *t == token) {
            let (_, seq, active) = deferred.swap_remove(i);
            self.send(active, seq, response);
            answered = true;
        }
        answered
    }

    /// Requests kept open, not yet answered.
    pub fn deferred(&self) -> usize {
        self.deferred.borrow().len()
    }

    fn send(&self, active: Active, seq: u64, mut response: ControlResponse) {
        response.seq = seq;
        // A client that gave up (timed out and dropped its pending response) makes
        // this fail; that must not stop the daemon from serving the others.
        if let Err(e) = active.send_copy(response) {
            tracing::debug!(service = %self.service, error = ?e, "control response not delivered");
        }
    }

    /// Full service name.
    pub fn service_name(&self) -> &str {
        &self.service
    }
}

/// Validates a request and decodes its kind; the error is the reason for the operator.
fn decode(request: &ControlRequest) -> Result<RequestKind, String> {
    request.validate().map_err(|r| r.to_string())?;
    request.kind().map_err(|e| e.to_string())
}

/// The operator's end of the control service. Not `Send`.
#[derive(Debug)]
pub struct ControlClient {
    client: Client<Ipc, ControlRequest, (), ControlResponse, ()>,
    notifier: Notifier<Ipc>,
    service: String,
    next_seq: Cell<u64>,
}

impl ControlClient {
    /// Opens or creates the control service and creates the client.
    pub fn create(node: &IpcNode, ipc: &IpcConfig) -> Result<Self, IpcError> {
        let (service, factory) = open_control(node, ipc)?;
        let client = factory
            .client_builder()
            .create()
            .map_err(ice("create client", &service))?;
        let notifier = open_event(node, &service)?
            .notifier_builder()
            .create()
            .map_err(ice("create notifier", &service))?;
        Ok(Self {
            client,
            notifier,
            service,
            next_seq: Cell::new(1),
        })
    }

    /// Sends `request` (its `seq` is assigned here), wakes the server and waits up to
    /// `timeout` for the validated response.
    pub fn call(
        &self,
        mut request: ControlRequest,
        timeout: Duration,
    ) -> Result<ControlResponse, IpcError> {
        let seq = self.next_seq.get();
        self.next_seq.set(seq + 1);
        request.seq = seq;
        let pending = self
            .client
            .send_copy(request)
            .map_err(ice("send request", &self.service))?;
        if pending.number_of_server_connections() == 0 {
            return Err(IpcError::NoServer {
                service: self.service.clone(),
            });
        }
        self.notifier
            .notify()
            .map_err(ice("notify", &self.service))?;
        let start = Instant::now();
        loop {
            if let Some(response) = pending
                .receive()
                .map_err(ice("receive response", &self.service))?
            {
                let response = *response.payload();
                response
                    .validate()
                    .map_err(|reason| IpcError::InvalidResponse {
                        service: self.service.clone(),
                        reason,
                    })?;
                if response.seq != seq {
                    return Err(IpcError::ResponseMismatch {
                        service: self.service.clone(),
                        expected: seq,
                        got: response.seq,
                    });
                }
                return Ok(response);
            }
            if start.elapsed() >= timeout {
                return Err(IpcError::Timeout {
                    service: self.service.clone(),
                    timeout,
                });
            }
            std::thread::sleep(RESPONSE_POLL);
        }
    }

    /// Full service name.
    pub fn service_name(&self) -> &str {
        &self.service
    }
}
