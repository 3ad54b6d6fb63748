//! The syntax tree of a teleo-reactive program, as the parser builds it and the checker and evaluator read it.

use std::collections::BTreeMap;
use std::time::Duration;

use crate::value::Value;

/// A position in the program text (1-based line and column, columns counted in characters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Pos {
    pub line: u32,
    pub col: u32,
}

/// Whether a declared predicate is sensed (`percept`, asserted by the host) or remembered (`belief`, asserted by
/// the program's own `remember` actions).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeclKind {
    Percept,
    Belief,
}

/// The declared type of one predicate argument.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArgType {
    Text,
    Num,
    Bool,
    Any,
}

impl ArgType {
    pub fn name(self) -> &'static str {
        match self {
            ArgType::Text => "text",
            ArgType::Num => "num",
            ArgType::Bool => "bool",
            ArgType::Any => "any",
        }
    }

    /// Whether a value may be stored in an argument of this type.
    pub fn admits(self, value: &Value) -> bool {
        matches!(
            (self, value),
            (ArgType::Any, _)
                | (ArgType::Text, Value::Text(_))
                | (ArgType::Num, Value::Num(_))
                | (ArgType::Bool, Value::Bool(_))
        )
    }
}

/// `percept face(num, text) fresh 2s` or `belief greeted`.
#[derive(Debug, Clone)]
pub struct Decl {
    pub name: String,
    pub kind: DeclKind,
    pub args: Vec<ArgType>,
    /// Events (`heard`) make a new fact each time they are sensed, even with the same value; states (`face`)
    /// refresh the fact they already have while the value stays the same.
    pub event: bool,
    /// How long after it was last sensed a fact is still believed; `None` keeps it until it is retracted.
    pub fresh: Option<Duration>,
    pub pos: Pos,
}

/// `tool "Robot.command" "turns the robot's head" {action: ["turn"], direction: ["left", "right"]}`: a service
/// the language model may call when a rule hands it the turn with `chat(T, "Robot.command")`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ToolDecl {
    /// The service channel the host calls with the model's arguments.
    pub service: String,
    /// What the service does, told to the model so that it picks the right values.
    pub description: String,
    /// Each argument is a text field limited to the listed values (never empty).
    pub args: BTreeMap<String, Vec<String>>,
    pub pos: Pos,
}

/// `procedure name(Params) { rules }`.
#[derive(Debug, Clone)]
pub struct Procedure {
    pub name: String,
    pub params: Vec<String>,
    pub rules: Vec<Rule>,
    pub pos: Pos,
}

/// `label: guard ~> durative actions ++ discrete actions`.
#[derive(Debug, Clone)]
pub struct Rule {
    pub label: String,
    pub guard: Guard,
    pub durative: Vec<ActionExpr>,
    pub discrete: Vec<ActionExpr>,
    pub pos: Pos,
}

/// A guard: a query on the belief store.
#[derive(Debug, Clone)]
pub enum Guard {
    True,
    Atom(AtomExpr),
    Not(Box<Guard>),
    And(Vec<Guard>),
    Or(Vec<Guard>),
    Compare(Expr, CompareOp, Expr),
}

/// A predicate in a guard, `face(N, _)`, optionally with a time qualifier.
#[derive(Debug, Clone)]
pub struct AtomExpr {
    pub name: String,
    pub args: Vec<Expr>,
    pub temporal: Option<Temporal>,
    pub pos: Pos,
}

/// Time qualifiers on an atom.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Temporal {
    /// `face(_, _) within 10s`: sensed at some point in the last 10 seconds, fresh or not.
    Within(Duration),
    /// `face(_, _) for 1s`: fresh and continuously present for at least a second.
    For(Duration),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CompareOp {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    /// `T ~ "what time"`: fuzzy phrase match of normalised speech.
    Like,
}

/// An expression: an argument of an atom, a side of a comparison, an action argument or a template hole.
#[derive(Debug, Clone)]
pub enum Expr {
    Var(String, Pos),
    /// `_`: matches anything in an atom argument.
    Wild(Pos),
    Lit(Value, Pos),
    /// A string with `{...}` holes.
    Template(Vec<TemplatePart>, Pos),
    /// A dotted clock field such as `time.hhmm`.
    Path(Vec<String>, Pos),
    /// A built-in function (`plural(N, "person", "people")`) or, in a guard, a predicate.
    Call(String, Vec<Expr>, Pos),
    List(Vec<Expr>, Pos),
    Map(Vec<(String, Expr)>, Pos),
}

impl Expr {
    pub fn pos(&self) -> Pos {
        match self {
            Expr::Var(_, pos)
            | Expr::Wild(pos)
            | Expr::Lit(_, pos)
            | Expr::Template(_, pos)
            | Expr::Path(_, pos)
            | Expr::Call(_, _, pos)
            | Expr::List(_, pos)
            | Expr::Map(_, pos) => *pos,
        }
    }
}

#[derive(Debug, Clone)]
pub enum TemplatePart {
    Text(String),
    Hole(Expr),
}

/// The primitive actions a rule can take; everything else named in an action list is a procedure call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Primitive {
    Say,
    Publish,
    Call,
    Run,
    Set,
    Cancel,
    Remember,
    Forget,
    /// `chat(T)` or `chat(T, "Service.name")`: hand the turn to the language model.
    Chat,
    /// `forget_conversation`: the host forgets the language model's chat memory.
    ForgetConversation,
    /// `recall(T)`: say the knowledge folder's best passage for `T`.
    Recall,
    /// `learn_face(Name)`: remember the talking person's face under a name.
    LearnFace,
    /// `forget_face`: erase the talking person's stored face.
    ForgetFace,
    /// `mood(M)`: an expression on the avatar for a few seconds.
    Mood,
}

impl Primitive {
    pub fn from_name(name: &str) -> Option<Primitive> {
        Some(match name {
            "say" => Primitive::Say,
            "publish" => Primitive::Publish,
            "call" => Primitive::Call,
            "run" => Primitive::Run,
            "set" => Primitive::Set,
            "cancel" => Primitive::Cancel,
            "remember" => Primitive::Remember,
            "forget" => Primitive::Forget,
            "chat" => Primitive::Chat,
            "forget_conversation" => Primitive::ForgetConversation,
            "recall" => Primitive::Recall,
            "learn_face" => Primitive::LearnFace,
            "forget_face" => Primitive::ForgetFace,
            "mood" => Primitive::Mood,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Primitive::Say => "say",
            Primitive::Publish => "publish",
            Primitive::Call => "call",
            Primitive::Run => "run",
            Primitive::Set => "set",
            Primitive::Cancel => "cancel",
            Primitive::Remember => "remember",
            Primitive::Forget => "forget",
            Primitive::Chat => "chat",
            Primitive::ForgetConversation => "forget_conversation",
            Primitive::Recall => "recall",
            Primitive::LearnFace => "learn_face",
            Primitive::ForgetFace => "forget_face",
            Primitive::Mood => "mood",
        }
    }

    /// The fewest and the most arguments the primitive takes.
    pub fn arity(self) -> (usize, usize) {
        match self {
            Primitive::Say
            | Primitive::Run
            | Primitive::Remember
            | Primitive::Forget
            | Primitive::Recall
            | Primitive::LearnFace
            | Primitive::Mood => (1, 1),
            Primitive::Publish | Primitive::Call | Primitive::Set => (2, 2),
            Primitive::Cancel | Primitive::ForgetConversation | Primitive::ForgetFace => (0, 0),
            // The optional second argument names the tool the model must call.
            Primitive::Chat => (1, 2),
        }
    }

    /// Whether the primitive only makes sense once, on entry (it has nothing to stop on exit).
    pub fn discrete_only(self) -> bool {
        // A chat turn is one exchange with the model, so it fires once like a belief update; it has no
        // utterance of its own that a rule could stop.
        matches!(
            self,
            Primitive::Cancel
                | Primitive::Remember
                | Primitive::Forget
                | Primitive::Chat
                | Primitive::ForgetConversation
                | Primitive::Recall
                | Primitive::LearnFace
                | Primitive::ForgetFace
                | Primitive::Mood
        )
    }
}

/// An action in a rule's action list.
#[derive(Debug, Clone)]
pub enum ActionExpr {
    Primitive {
        primitive: Primitive,
        args: Vec<Expr>,
        pos: Pos,
    },
    Procedure {
        name: String,
        args: Vec<Expr>,
        pos: Pos,
    },
}
