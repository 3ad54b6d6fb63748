//! One connection's protocol state machine: login first, then commands mapped
//! onto the hub core and the pair database. No socket here either: commands
//! come in as values and replies go out through the connection's outbox.

use std::sync::Arc;

use flow::protocol::{
    Command, Envelope, ErrorCode, ErrorReply, Event, PROTOCOL_VERSION, Reply, ReqId,
};
use tracing::{debug, info, warn};

use crate::hub::{ConnId, Outbox};
use crate::pairdb::{DEFAULT_DB, PairDbError};
use crate::server::Shared;

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

/// Per-connection protocol state.
#[derive(Debug)]
pub struct Session {
    conn: ConnId,
    peer: String,
    outbox: Arc<Outbox>,
    shared: Arc<Shared>,
    stage: Stage,
    db: String,
    is_async: bool,
    /// Connections made inside the server by modules are trusted as admins.
    internal: bool,
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
    pub fn new(
        conn: ConnId,
        peer: String,
        outbox: Arc<Outbox>,
        shared: Arc<Shared>,
        internal: bool,
    ) -> Self {
        Session {
            conn,
            peer,
            outbox,
            shared,
            stage: Stage::AwaitLogin,
            db: DEFAULT_DB.into(),
            is_async: false,
            internal,
        }
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
                self.shared.hub.set_async(self.conn);
                Ok(Reply::Done)
            }
            Command::AddChannel { kind, name, header } => {
                if let Err(e) = check_json_object(&header) {
                    refuse(ErrorCode::BadRequest, format!("header of {name}: {e}"))
                } else {
                    self.shared
                        .hub
                        .add_channel(self.conn, kind, &name, &header)
                        .map(Reply::Channel)
                }
            }
            Command::RemoveChannel { chan } => self
                .shared
                .hub
                .remove_channel(self.conn, &chan)
                .map(|()| Reply::Done),
            Command::SetHeader { chan, header } => match check_json_object(&header) {
                Err(e) => refuse(ErrorCode::BadRequest, format!("header: {e}")),
                Ok(()) => self
                    .shared
                    .hub
                    .set_header(self.conn, chan, &header)
                    .map(|()| Reply::Done),
            },
            Command::Subscribe { chan } => self
                .shared
                .hub
                .subscribe(self.conn, &chan)
                .map(Reply::Channel),
            Command::Unsubscribe { chan } => self
                .shared
                .hub
                .unsubscribe(self.conn, &chan)
                .map(|()| Reply::Done),
            Command::Publish { chan, payload } => self
                .shared
                .hub
                .publish(self.conn, chan, payload)
                .map(|()| Reply::Done),
            Command::Call {
                chan,
                timeout_ms,
                payload,
            } => match self
                .shared
                .hub
                .call(self.conn, req, &chan, payload, timeout_ms)
            {
                // The reply comes from the service owner, or from the hub's
                // call timer once the timeout has passed.
                Ok(_) => return Outcome::Continue,
                Err(e) => Err(e),
            },
            Command::Respond { call, result } => self
                .shared
                .hub
                .respond(self.conn, call, result)
                .map(|()| Reply::Done),
            Command::ListChannels => Ok(Reply::Channels(self.shared.hub.list_channels())),
            Command::GetChannel { chan } => self.shared.hub.channel(&chan).map(Reply::Channel),
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
        let Some(admin) = self.shared.tokens.check(&token) else {
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
        self.shared.hub.login(self.conn, &name, admin);
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
        F: FnOnce(&crate::pairdb::PairDb) -> Result<T, PairDbError> + Send + 'static,
    {
        let db = self.shared.pairdb.clone();
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
            Ok(Err(PairDbError::Storage(e))) => {
                warn!("pair database error: {e}");
                Err(ErrorReply::new(ErrorCode::Database, e))
            }
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
