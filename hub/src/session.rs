//! One connection's protocol state machine: login first, then commands mapped
//! onto the hub core and the pair database. No socket here either: commands
//! come in as values and replies go out through the connection's outbox.

use std::sync::Arc;

use flow::protocol::{
    Command, Envelope, ErrorCode, ErrorReply, Event, PROTOCOL_VERSION, Reply, ReqId,
};
use tracing::{debug, info};

use crate::hub::{ConnId, Hub, LeaseError, Outbox, ShmPeer};
use crate::pairdb::{DEFAULT_DB, PairDb, PairDbError};
use crate::tokens::Tokens;

/// What the connection driver should do after a command.
#[derive(Debug, PartialEq, Eq)]
pub enum Outcome {
    Continue,
    /// Close this connection, logging the reason.
    Close(String),
}

#[derive(Debug, PartialEq, Eq)]
enum Stage {
    AwaitLogin,
    Ready,
}

/// What a session needs from the server, and nothing more: the hub its
/// commands act on, the pair database and the tokens a login is checked
/// against. Built from the server's shared state by the connection driver, or
/// by hand in tests, without a server.
#[derive(Debug, Clone)]
pub struct SessionContext {
    pub hub: Arc<Hub>,
    pub pairdb: Arc<PairDb>,
    pub tokens: Tokens,
}

/// Per-connection protocol state.
#[derive(Debug)]
pub struct Session {
    conn: ConnId,
    peer: String,
    outbox: Arc<Outbox>,
    hub: Arc<Hub>,
    pairdb: Arc<PairDb>,
    tokens: Tokens,
    stage: Stage,
    db: String,
    is_async: bool,
    /// Connections made inside the server by modules are trusted as admins.
    internal: bool,
    /// Shared memory, on a connection that can take it (the Unix socket).
    shm: Option<Arc<ShmPeer>>,
}

type CmdResult = Result<Reply, ErrorReply>;

fn refuse(code: ErrorCode, message: impl Into<String>) -> CmdResult {
    Err(ErrorReply::new(code, message))
}

/// The reply of a command that has nothing to say but that it worked.
fn done(_: ()) -> Reply {
    Reply::Done
}

impl Session {
    /// A session for connection `conn` (already known to `context.hub`), not
    /// logged in yet. `internal` marks the server's own modules.
    pub fn new(
        conn: ConnId,
        peer: String,
        outbox: Arc<Outbox>,
        context: SessionContext,
        internal: bool,
    ) -> Self {
        let SessionContext {
            hub,
            pairdb,
            tokens,
        } = context;
        Session {
            conn,
            peer,
            outbox,
            hub,
            pairdb,
            tokens,
            stage: Stage::AwaitLogin,
            db: DEFAULT_DB.into(),
            is_async: false,
            internal,
            shm: None,
        }
    }

    /// Offers shared memory on this connection (its transport passes descriptors).
    pub fn set_shm_peer(&mut self, peer: Option<Arc<ShmPeer>>) {
        self.shm = peer;
    }

    /// The connection's shared memory once the client accepted it.
    fn accepted_shm(&self) -> Option<&Arc<ShmPeer>> {
        self.shm.as_ref().filter(|peer| peer.accepted())
    }

    /// Whether the connection has logged in.
    pub fn is_logged_in(&self) -> bool {
        self.stage == Stage::Ready
    }

    /// Handles one decoded command.
    pub async fn handle(&mut self, env: Envelope) -> Outcome {
        let Envelope { req, command } = env;
        if self.stage == Stage::AwaitLogin {
            return self.login(req, command);
        }
        let result = match command {
            Command::Login { .. } => refuse(ErrorCode::BadRequest, "already logged in"),
            Command::SetAsync => {
                self.is_async = true;
                self.hub.set_async(self.conn);
                Ok(Reply::Done)
            }
            Command::AddChannel { kind, name, header } => {
                if let Err(e) = check_json_object(&header) {
                    refuse(ErrorCode::BadRequest, format!("header of {name}: {e}"))
                } else {
                    self.hub
                        .add_channel(self.conn, kind, &name, &header)
                        .map(Reply::Channel)
                }
            }
            Command::RemoveChannel { chan } => self
                .hub
                .remove_channel(self.conn, &chan)
                .map(|()| Reply::Done),
            Command::SetHeader { chan, header } => match check_json_object(&header) {
                Err(e) => refuse(ErrorCode::BadRequest, format!("header: {e}")),
                Ok(()) => self
                    .hub
                    .set_header(self.conn, chan, &header)
                    .map(|()| Reply::Done),
            },
            Command::Subscribe { chan } => match self.hub.subscribe_acked(self.conn, &chan, req) {
                // The hub has queued the reply itself, ahead of the channel's first message.
                Ok(_) => return Outcome::Continue,
                Err(e) => Err(e),
            },
            Command::Unsubscribe { chan } => {
                self.hub.unsubscribe(self.conn, &chan).map(|()| Reply::Done)
            }
            Command::Publish { chan, payload } => self
                .hub
                .publish(self.conn, chan, payload)
                .map(|()| Reply::Done),
            Command::Call {
                chan,
                timeout_ms,
                payload,
            } => match self.hub.call(self.conn, req, &chan, payload, timeout_ms) {
                // The reply comes from the service owner, or from the hub's
                // call timer once the timeout has passed.
                Ok(_) => return Outcome::Continue,
                Err(e) => Err(e),
            },
            Command::Respond { call, result } => self
                .hub
                .respond(self.conn, call, result)
                .map(|()| Reply::Done),
            Command::ListChannels => Ok(Reply::Channels(self.hub.list_channels())),
            Command::GetChannel { chan } => self.hub.channel(&chan).map(Reply::Channel),
            Command::DbSelect { name } => self.db_select(name).await,
            Command::DbCreate { name } => self.db_op(move |db| db.create(&name)).await.map(done),
            Command::DbRemove { name } => self.db_op(move |db| db.remove(&name)).await.map(done),
            Command::DbList => self.db_op(|db| db.list()).await.map(Reply::Names),
            Command::VarSet { key, value } => {
                match serde_json::from_str::<serde_json::Value>(&value) {
                    Err(e) => refuse(
                        ErrorCode::BadRequest,
                        format!("value of {key} is not JSON: {e}"),
                    ),
                    Ok(_) => {
                        let current = self.db.clone();
                        self.db_op(move |db| db.set(&current, &key, &value))
                            .await
                            .map(done)
                    }
                }
            }
            Command::VarGet { key } => {
                let current = self.db.clone();
                let probe = key.clone();
                match self.db_op(move |db| db.get(&current, &probe)).await {
                    Ok(Some(value)) => Ok(Reply::Value(value)),
                    Ok(None) => refuse(ErrorCode::NotFound, format!("no variable {key}")),
                    Err(e) => Err(e),
                }
            }
            Command::VarDel { key } => {
                let current = self.db.clone();
                // Deleting a variable that is not there is not an error.
                self.db_op(move |db| db.del(&current, &key))
                    .await
                    .map(|_existed| Reply::Done)
            }
            Command::VarList => {
                let current = self.db.clone();
                self.db_op(move |db| db.keys(&current))
                    .await
                    .map(Reply::Names)
            }
            Command::Ping => Ok(Reply::Pong),
            Command::ShmAccept => match &self.shm {
                Some(peer) if self.is_async => {
                    peer.accept();
                    let threshold = self.hub.segments().settings().threshold;
                    Ok(Reply::Shm { threshold })
                }
                Some(_) => refuse(
                    ErrorCode::BadRequest,
                    "shared memory needs an asynchronous connection (SetAsync first)",
                ),
                None => refuse(
                    ErrorCode::BadRequest,
                    "shared memory is offered only over the hub's Unix socket, and only when hub.shm is on",
                ),
            },
            Command::ShmOpen { chan, slot_size } => match self.accepted_shm() {
                Some(_) => self
                    .hub
                    .shm_open(self.conn, chan, slot_size)
                    .map(Reply::Segment),
                None => refuse(ErrorCode::BadRequest, "ShmAccept first"),
            },
            Command::PublishRef { chan, slot } => {
                if self.accepted_shm().is_none() {
                    return Outcome::Close("a message by reference without ShmAccept".into());
                }
                match self.hub.publish_ref(self.conn, chan, slot) {
                    Ok(()) => Ok(Reply::Done),
                    Err(LeaseError::Unknown(e)) => refuse(ErrorCode::NotFound, e),
                    Err(LeaseError::Violation(e)) => return Outcome::Close(e),
                }
            }
            Command::Release { slots } => {
                if let Some(peer) = &self.shm
                    && let Err(e) = peer.release(&slots)
                {
                    return Outcome::Close(e.to_string());
                }
                Ok(Reply::Done)
            }
        };
        self.reply(req, result);
        Outcome::Continue
    }

    fn login(&mut self, req: ReqId, command: Command) -> Outcome {
        let Command::Login {
            version,
            token,
            name,
        } = command
        else {
            self.reply(req, refuse(ErrorCode::NotAuthenticated, "log in first"));
            return Outcome::Close("command before login".into());
        };
        if version != PROTOCOL_VERSION {
            let msg = format!(
                "protocol version {version} is not supported (server speaks {PROTOCOL_VERSION})"
            );
            self.reply(req, refuse(ErrorCode::VersionMismatch, msg.clone()));
            return Outcome::Close(msg);
        }
        let Some(admin) = self.tokens.check(&token) else {
            // Never log the token itself.
            self.reply(req, refuse(ErrorCode::AuthFailed, "wrong token"));
            return Outcome::Close(format!("login as {name:?} refused: wrong token"));
        };
        if let Err(reason) = flow::protocol::validate_name(&name) {
            self.reply(
                req,
                refuse(ErrorCode::BadRequest, format!("login name: {reason}")),
            );
            return Outcome::Close(format!("bad login name: {reason}"));
        }
        let admin = admin || self.internal;
        self.stage = Stage::Ready;
        self.hub.login(self.conn, &name, admin);
        info!(peer = %self.peer, conn = self.conn, admin, "{name} logged in");
        let server = format!("robot-agent {}", env!("CARGO_PKG_VERSION"));
        self.reply(
            req,
            Ok(Reply::LoginOk {
                version: PROTOCOL_VERSION,
                conn: self.conn,
                admin,
                server,
            }),
        );
        Outcome::Continue
    }

    async fn db_select(&mut self, name: String) -> CmdResult {
        let probe = name.clone();
        if !self.db_op(move |db| db.exists(&probe)).await? {
            return refuse(ErrorCode::NoDatabase, format!("no database named {name}"));
        }
        self.db = name.clone();
        if self.is_async {
            self.outbox.push_control(Event::DbChanged { name });
        }
        Ok(Reply::Done)
    }

    /// Runs a pair-database operation on the blocking pool (writes fsync) and
    /// turns its errors into the protocol's: a missing database is
    /// `NoDatabase`, never `NotFound`, which means a missing key.
    async fn db_op<T, F>(&self, op: F) -> Result<T, ErrorReply>
    where
        T: Send + 'static,
        F: FnOnce(&PairDb) -> Result<T, PairDbError> + Send + 'static,
    {
        let db = self.pairdb.clone();
        match tokio::task::spawn_blocking(move || op(&db)).await {
            Ok(Ok(value)) => Ok(value),
            Ok(Err(PairDbError::NoDatabase(n))) => Err(ErrorReply::new(
                ErrorCode::NoDatabase,
                format!("no database named {n}"),
            )),
            Ok(Err(PairDbError::Exists(n))) => Err(ErrorReply::new(
                ErrorCode::Exists,
                format!("database {n} already exists"),
            )),
            // Both logged by the store itself (at most once a minute: they repeat on every call); after an I/O
            // error it opens the database again at the next call.
            Ok(Err(PairDbError::Storage(e))) => Err(ErrorReply::new(ErrorCode::Database, e)),
            Ok(Err(PairDbError::Io(e))) => Err(ErrorReply::new(
                ErrorCode::Database,
                format!("the disk failed, nothing was written: {e}"),
            )),
            Err(e) => Err(ErrorReply::new(
                ErrorCode::Internal,
                format!("database task failed: {e}"),
            )),
        }
    }

    fn reply(&self, req: ReqId, result: CmdResult) {
        if req == 0 {
            match result {
                Ok(_) => return,
                // Nobody waits for a fire-and-forget command; still tell the
                // client why it failed, with request id 0.
                Err(ref e) => debug!(conn = self.conn, "fire-and-forget command refused: {e}"),
            }
        }
        self.outbox.push_control(Event::Reply { req, result });
    }
}

/// Channel headers are JSON objects.
fn check_json_object(text: &str) -> Result<(), String> {
    match serde_json::from_str::<serde_json::Value>(text) {
        Ok(serde_json::Value::Object(_)) => Ok(()),
        Ok(_) => Err("must be a JSON object".into()),
        Err(e) => Err(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    //! The session on its own: a real hub, a real pair database and real
    //! tokens in a temporary directory, commands in and replies out of the
    //! outbox, no socket and no server.

    use std::time::{Duration, Instant};

    use flow::protocol::{ChanRef, ChannelKind};

    use super::*;
    use crate::hub::{HubLimits, MAX_CHANNELS, OutboxLimits};
    use crate::tokens::TOKEN_FILE;

    /// A hub, a pair database and tokens in a directory that is removed with it.
    struct Bench {
        context: SessionContext,
        user_token: String,
        _dir: tempfile::TempDir,
    }

    impl Bench {
        fn new() -> Bench {
            let dir = tempfile::tempdir().expect("temporary directory");
            let tokens = Tokens::load_or_create(dir.path()).expect("tokens");
            let user_token = std::fs::read_to_string(dir.path().join(TOKEN_FILE))
                .expect("user token file")
                .trim()
                .to_owned();
            let pairdb = PairDb::open(&dir.path().join("pairs.redb")).expect("pair database");
            let hub = Hub::new(HubLimits {
                outbox: OutboxLimits {
                    lane_msgs: 64,
                    lane_bytes: 1 << 20,
                    control_msgs: 1024,
                },
                service_inflight: 8,
                max_channels: MAX_CHANNELS,
            });
            Bench {
                context: SessionContext {
                    hub: Arc::new(hub),
                    pairdb: Arc::new(pairdb),
                    tokens,
                },
                user_token,
                _dir: dir,
            }
        }

        /// A new connection's session and its outbox, not logged in.
        fn session(&self) -> (Session, Arc<Outbox>) {
            let (conn, outbox) = self.context.hub.connect("test");
            let session = Session::new(
                conn,
                "test".into(),
                outbox.clone(),
                self.context.clone(),
                false,
            );
            (session, outbox)
        }

        /// A session logged in with the user token.
        async fn logged_in(&self, name: &str) -> (Session, Arc<Outbox>) {
            let (mut session, outbox) = self.session();
            let token = self.user_token.clone();
            let outcome = session
                .handle(login(1, PROTOCOL_VERSION, &token, name))
                .await;
            assert_eq!(outcome, Outcome::Continue);
            assert!(session.is_logged_in());
            assert!(matches!(
                replies(&outbox).as_slice(),
                [(1, Ok(Reply::LoginOk { admin: false, .. }))]
            ));
            (session, outbox)
        }
    }

    fn login(req: ReqId, version: u16, token: &str, name: &str) -> Envelope {
        Envelope {
            req,
            command: Command::Login {
                version,
                token: token.into(),
                name: name.into(),
            },
        }
    }

    fn events(outbox: &Outbox) -> Vec<Event> {
        let mut out = Vec::new();
        outbox.pop_batch(&mut out, usize::MAX);
        out
    }

    /// The replies queued so far, as (request id, result).
    fn replies(outbox: &Outbox) -> Vec<(ReqId, CmdResult)> {
        events(outbox)
            .into_iter()
            .filter_map(|e| match e {
                Event::Reply { req, result } => Some((req, result)),
                _ => None,
            })
            .collect()
    }

    /// Sends one command with request id `req` and returns its reply.
    async fn ask(
        session: &mut Session,
        outbox: &Outbox,
        req: ReqId,
        command: Command,
    ) -> CmdResult {
        assert_eq!(
            session.handle(Envelope { req, command }).await,
            Outcome::Continue
        );
        let mut got = replies(outbox);
        assert_eq!(got.len(), 1, "one reply to request {req}: {got:?}");
        let (r, result) = got.remove(0);
        assert_eq!(r, req);
        result
    }

    fn code(result: CmdResult) -> ErrorCode {
        match result {
            Err(e) => e.code,
            Ok(reply) => panic!("expected a refusal, got {reply:?}"),
        }
    }

    #[tokio::test]
    async fn a_login_with_a_wrong_token_is_refused_and_closes_the_connection() {
        let bench = Bench::new();
        let (mut session, outbox) = bench.session();
        let outcome = session
            .handle(login(1, PROTOCOL_VERSION, "not-the-token", "intruder"))
            .await;
        assert!(matches!(outcome, Outcome::Close(ref why) if why.contains("wrong token")));
        assert!(!session.is_logged_in());
        let got = replies(&outbox);
        assert_eq!(got.len(), 1);
        assert_eq!(code(got[0].1.clone()), ErrorCode::AuthFailed);
        // The refusal never echoes what was presented.
        assert!(!format!("{got:?}").contains("not-the-token"));
    }

    #[tokio::test]
    async fn a_login_speaking_another_protocol_version_is_refused() {
        let bench = Bench::new();
        let (mut session, outbox) = bench.session();
        let token = bench.user_token.clone();
        let outcome = session
            .handle(login(1, PROTOCOL_VERSION + 1, &token, "future"))
            .await;
        assert!(matches!(outcome, Outcome::Close(_)));
        assert!(!session.is_logged_in());
        let got = replies(&outbox);
        assert_eq!(code(got[0].1.clone()), ErrorCode::VersionMismatch);
    }

    #[tokio::test]
    async fn a_command_before_login_is_refused_and_closes_the_connection() {
        let bench = Bench::new();
        let (mut session, outbox) = bench.session();
        let outcome = session
            .handle(Envelope {
                req: 4,
                command: Command::ListChannels,
            })
            .await;
        assert_eq!(outcome, Outcome::Close("command before login".into()));
        let got = replies(&outbox);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, 4);
        assert_eq!(code(got[0].1.clone()), ErrorCode::NotAuthenticated);
    }

    #[tokio::test]
    async fn the_admin_token_logs_in_as_admin_and_a_second_login_is_refused() {
        let bench = Bench::new();
        let (mut session, outbox) = bench.session();
        let admin = bench.context.tokens.admin().to_owned();
        assert_eq!(
            session
                .handle(login(1, PROTOCOL_VERSION, &admin, "root"))
                .await,
            Outcome::Continue
        );
        assert!(matches!(
            replies(&outbox).as_slice(),
            [(1, Ok(Reply::LoginOk { admin: true, .. }))]
        ));
        let again = ask(
            &mut session,
            &outbox,
            2,
            Command::Login {
                version: PROTOCOL_VERSION,
                token: admin,
                name: "root".into(),
            },
        )
        .await;
        assert_eq!(code(again), ErrorCode::BadRequest);
    }

    #[tokio::test]
    async fn a_variable_is_set_read_and_deleted() {
        let bench = Bench::new();
        let (mut s, ob) = bench.logged_in("db-user").await;
        let set = Command::VarSet {
            key: "robot.pose".into(),
            value: r#"{"x":1.5}"#.into(),
        };
        assert_eq!(ask(&mut s, &ob, 2, set).await, Ok(Reply::Done));
        let get = || Command::VarGet {
            key: "robot.pose".into(),
        };
        assert_eq!(
            ask(&mut s, &ob, 3, get()).await,
            Ok(Reply::Value(r#"{"x":1.5}"#.into()))
        );
        assert_eq!(
            ask(&mut s, &ob, 4, Command::VarList).await,
            Ok(Reply::Names(vec!["robot.pose".into()]))
        );
        let del = || Command::VarDel {
            key: "robot.pose".into(),
        };
        assert_eq!(ask(&mut s, &ob, 5, del()).await, Ok(Reply::Done));
        // Gone: a missing key is NotFound, and deleting it again is no error.
        assert_eq!(code(ask(&mut s, &ob, 6, get()).await), ErrorCode::NotFound);
        assert_eq!(ask(&mut s, &ob, 7, del()).await, Ok(Reply::Done));
        // Values must be JSON.
        let bad = Command::VarSet {
            key: "k".into(),
            value: "{not json".into(),
        };
        assert_eq!(code(ask(&mut s, &ob, 8, bad).await), ErrorCode::BadRequest);
    }

    #[tokio::test]
    async fn a_missing_database_is_no_database_and_not_a_missing_key() {
        let bench = Bench::new();
        let (mut s, ob) = bench.logged_in("db-user").await;
        let select = |name: &str| Command::DbSelect { name: name.into() };
        assert_eq!(
            code(ask(&mut s, &ob, 2, select("nowhere")).await),
            ErrorCode::NoDatabase
        );
        assert_eq!(
            code(
                ask(
                    &mut s,
                    &ob,
                    3,
                    Command::DbRemove {
                        name: "nowhere".into()
                    }
                )
                .await
            ),
            ErrorCode::NoDatabase
        );
        let create = Command::DbCreate {
            name: "robot".into(),
        };
        assert_eq!(ask(&mut s, &ob, 4, create.clone()).await, Ok(Reply::Done));
        assert_eq!(code(ask(&mut s, &ob, 5, create).await), ErrorCode::Exists);
        assert_eq!(ask(&mut s, &ob, 6, select("robot")).await, Ok(Reply::Done));
        // Once the current database is removed, reading a key in it is an
        // error about the database, not "no such key".
        assert_eq!(
            ask(
                &mut s,
                &ob,
                7,
                Command::DbRemove {
                    name: "robot".into()
                }
            )
            .await,
            Ok(Reply::Done)
        );
        let get = Command::VarGet { key: "k".into() };
        assert_eq!(code(ask(&mut s, &ob, 8, get).await), ErrorCode::NoDatabase);
        assert_eq!(
            code(ask(&mut s, &ob, 9, Command::VarList).await),
            ErrorCode::NoDatabase
        );
        assert_eq!(
            ask(&mut s, &ob, 10, Command::DbList).await,
            Ok(Reply::Names(vec![DEFAULT_DB.into()]))
        );
    }

    #[tokio::test]
    async fn the_async_switch_lets_a_connection_serve_and_hear_events() {
        let bench = Bench::new();
        let (mut s, ob) = bench.logged_in("server").await;
        let add = || Command::AddChannel {
            kind: ChannelKind::Service,
            name: "Robot.move".into(),
            header: "{}".into(),
        };
        // A synchronous connection cannot own a service: nothing could reach it.
        assert_eq!(
            code(ask(&mut s, &ob, 2, add()).await),
            ErrorCode::BadRequest
        );
        assert_eq!(
            ask(&mut s, &ob, 3, Command::SetAsync).await,
            Ok(Reply::Done)
        );
        assert!(matches!(
            ask(&mut s, &ob, 4, add()).await,
            Ok(Reply::Channel(_))
        ));
        // Asynchronous now: it hears of channels, and of the database it selects.
        let (mut other, other_ob) = bench.logged_in("other").await;
        let stream = Command::AddChannel {
            kind: ChannelKind::Stream,
            name: "Robot.pose".into(),
            header: "{}".into(),
        };
        assert!(matches!(
            ask(&mut other, &other_ob, 2, stream).await,
            Ok(Reply::Channel(_))
        ));
        assert!(
            events(&ob)
                .iter()
                .any(|e| matches!(e, Event::ChannelAdded(c) if c.name == "Robot.pose"))
        );
        assert!(
            s.handle(Envelope {
                req: 5,
                command: Command::DbSelect {
                    name: DEFAULT_DB.into(),
                },
            })
            .await
                == Outcome::Continue
        );
        let got = events(&ob);
        assert!(
            got.iter()
                .any(|e| matches!(e, Event::DbChanged { name } if name == DEFAULT_DB))
        );
        // The other connection stayed synchronous: it heard nothing.
        assert!(events(&other_ob).is_empty());
    }

    #[tokio::test]
    async fn a_call_nobody_answers_times_out_through_the_hub_timer() {
        let bench = Bench::new();
        let (mut owner, owner_ob) = bench.logged_in("owner").await;
        assert_eq!(
            ask(&mut owner, &owner_ob, 2, Command::SetAsync).await,
            Ok(Reply::Done)
        );
        let add = Command::AddChannel {
            kind: ChannelKind::Service,
            name: "Slow.svc".into(),
            header: "{}".into(),
        };
        assert!(matches!(
            ask(&mut owner, &owner_ob, 3, add).await,
            Ok(Reply::Channel(_))
        ));
        let (mut caller, caller_ob) = bench.logged_in("caller").await;
        let call = Command::Call {
            chan: ChanRef::Name("Slow.svc".into()),
            timeout_ms: 20,
            payload: bytes::Bytes::new(),
        };
        // The reply is not immediate: it comes from the owner or the timer.
        assert_eq!(
            caller
                .handle(Envelope {
                    req: 9,
                    command: call
                })
                .await,
            Outcome::Continue
        );
        assert!(replies(&caller_ob).is_empty());
        let deadline = Instant::now() + Duration::from_secs(5);
        let mut got = Vec::new();
        while got.is_empty() && Instant::now() < deadline {
            tokio::time::sleep(Duration::from_millis(5)).await;
            got = replies(&caller_ob);
        }
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(got[0].0, 9);
        assert_eq!(code(got[0].1.clone()), ErrorCode::Timeout);
    }
}
