//! `ros2msg` schema text: the `.msg` definition of a type with its dependencies appended after
//! `====` lines, each headed `MSG: pkg/Type` (what `ros2 bag record` stores in every MCAP).
//!
//! Parsing it gives a [`MsgDefs`] from which any message of the type can be decoded from CDR
//! without compiled message packages.

use crate::{Error, Result};
use std::collections::HashMap;

/// A primitive field type of the ROS 2 IDL.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Primitive {
    /// `bool` (1 byte).
    Bool,
    /// `byte`, `uint8`, `char` (1 byte, unsigned).
    U8,
    /// `int8`.
    I8,
    /// `int16`.
    I16,
    /// `uint16`.
    U16,
    /// `int32`.
    I32,
    /// `uint32`.
    U32,
    /// `int64`.
    I64,
    /// `uint64`.
    U64,
    /// `float32`.
    F32,
    /// `float64`.
    F64,
    /// `string` or `string<=N` (u32 length including the NUL, bytes, NUL).
    String,
    /// `wstring` (rarely logged; decoding it is refused with a clear error).
    WString,
}

impl Primitive {
    fn parse(name: &str) -> Option<Primitive> {
        Some(match name {
            "bool" => Primitive::Bool,
            "byte" | "uint8" | "char" => Primitive::U8,
            "int8" => Primitive::I8,
            "int16" => Primitive::I16,
            "uint16" => Primitive::U16,
            "int32" => Primitive::I32,
            "uint32" => Primitive::U32,
            "int64" => Primitive::I64,
            "uint64" => Primitive::U64,
            "float32" => Primitive::F32,
            "float64" => Primitive::F64,
            "string" => Primitive::String,
            "wstring" => Primitive::WString,
            _ if name.starts_with("string<=") => Primitive::String,
            _ if name.starts_with("wstring<=") => Primitive::WString,
            _ => return None,
        })
    }

    /// Size in bytes, which is also the CDR alignment (strings: their u32 length).
    pub fn size(self) -> usize {
        match self {
            Primitive::Bool | Primitive::U8 | Primitive::I8 => 1,
            Primitive::I16 | Primitive::U16 => 2,
            Primitive::I32 | Primitive::U32 | Primitive::F32 => 4,
            Primitive::String | Primitive::WString => 4,
            Primitive::I64 | Primitive::U64 | Primitive::F64 => 8,
        }
    }

    /// The IDL name, for canonical layouts and messages.
    pub fn name(self) -> &'static str {
        match self {
            Primitive::Bool => "bool",
            Primitive::U8 => "uint8",
            Primitive::I8 => "int8",
            Primitive::I16 => "int16",
            Primitive::U16 => "uint16",
            Primitive::I32 => "int32",
            Primitive::U32 => "uint32",
            Primitive::I64 => "int64",
            Primitive::U64 => "uint64",
            Primitive::F32 => "float32",
            Primitive::F64 => "float64",
            Primitive::String => "string",
            Primitive::WString => "wstring",
        }
    }
}

/// A field's element type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FieldType {
    /// A primitive.
    Primitive(Primitive),
    /// A nested message, by index into [`MsgDefs::types`].
    Message(usize),
}

/// Array shape of a field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arity {
    /// A single value.
    Single,
    /// `T[N]`: exactly N elements, no length prefix.
    Fixed(usize),
    /// `T[]` or `T[<=N]`: u32 count then the elements (`bound` is checked on write only).
    Sequence {
        /// `Some(N)` for `T[<=N]`.
        bound: Option<usize>,
    },
}

/// One field of a message type.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// Field name.
    pub name: String,
    /// Element type.
    pub ty: FieldType,
    /// Array shape.
    pub arity: Arity,
    /// Default value text as written in the definition (`float64 x 1.5`), if any.
    pub default: Option<String>,
}

/// One message type: its full name (`pkg/msg/Type`) and fields (constants are skipped: they are
/// not serialized).
#[derive(Debug, Clone, PartialEq)]
pub struct MsgType {
    /// Full name, normalized to `pkg/msg/Type`.
    pub name: String,
    /// Fields in wire order.
    pub fields: Vec<Field>,
}

/// A parsed schema: the root type (index 0) and every type it depends on.
#[derive(Debug, Clone, PartialEq)]
pub struct MsgDefs {
    /// All types; `types[0]` is the root.
    pub types: Vec<MsgType>,
}

/// Normalizes `pkg/Type` and `pkg/msg/Type` to `pkg/msg/Type`.
pub fn normalize_type_name(name: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        [pkg, ty] => format!("{pkg}/msg/{ty}"),
        _ => name.to_string(),
    }
}

/// Built-in definitions ROS 2 tools sometimes leave out of the schema text.
fn builtin_definition(name: &str) -> Option<&'static str> {
    match name {
        "builtin_interfaces/msg/Time" | "builtin_interfaces/msg/Duration" => Some("int32 sec\nuint32 nanosec\n"),
        _ => None,
    }
}

struct RawField {
    type_text: String,
    name: String,
    default: Option<String>,
    line: usize,
}

struct RawType {
    name: String,
    fields: Vec<RawField>,
}

impl MsgDefs {
    /// Parses the schema text of `root_name` (e.g. `sensor_msgs/msg/JointState`).
    ///
    /// # Errors
    /// [`Error::MsgDef`] naming the type and line for an unknown type, a malformed field line or
    /// a nested type missing from the text.
    pub fn parse(root_name: &str, text: &str) -> Result<MsgDefs> {
        let root_name = normalize_type_name(root_name);
        let mut raw: Vec<RawType> = Vec::new();
        let mut current = RawType { name: root_name.clone(), fields: Vec::new() };
        for (i, line) in text.lines().enumerate() {
            let line_no = i + 1;
            let trimmed = line.trim();
            if trimmed.len() >= 3 && trimmed.chars().all(|c| c == '=') {
                raw.push(std::mem::replace(&mut current, RawType { name: String::new(), fields: Vec::new() }));
                continue;
            }
            if let Some(rest) = trimmed.strip_prefix("MSG:") {
                current.name = normalize_type_name(rest.trim());
                continue;
            }
            let content = strip_comment(trimmed);
            if content.is_empty() {
                continue;
            }
            let mut parts = content.splitn(2, char::is_whitespace);
            let type_text = parts.next().unwrap_or_default().to_string();
            let rest = parts.next().unwrap_or_default().trim();
            if rest.is_empty() {
                return Err(Error::MsgDef {
                    type_name: current_name(&current, &root_name),
                    line: line_no,
                    message: format!("field line `{content}` has a type but no name"),
                });
            }
            // `TYPE NAME=VALUE` is a constant: not on the wire.
            let name_end = rest.find(|c: char| c.is_whitespace() || c == '=').unwrap_or(rest.len());
            let (name, after) = rest.split_at(name_end);
            let after = after.trim_start();
            if after.starts_with('=') {
                continue;
            }
            let default = (!after.is_empty()).then(|| after.to_string());
            current.fields.push(RawField { type_text, name: name.to_string(), default, line: line_no });
        }
        raw.push(current);
        // Sections with no fields and no name (e.g. a trailing separator) carry nothing.
        raw.retain(|t| !t.name.is_empty() || !t.fields.is_empty());

        let mut index: HashMap<String, usize> = HashMap::new();
        for (i, t) in raw.iter().enumerate() {
            index.entry(t.name.clone()).or_insert(i);
        }
        let mut defs = MsgDefs { types: Vec::new() };
        let mut resolved: HashMap<String, usize> = HashMap::new();
        defs.resolve(&root_name, &raw, &index, &mut resolved, 0)?;
        Ok(defs)
    }

    fn resolve(
        &mut self,
        name: &str,
        raw: &[RawType],
        index: &HashMap<String, usize>,
        resolved: &mut HashMap<String, usize>,
        depth: usize,
    ) -> Result<usize> {
        if let Some(&i) = resolved.get(name) {
            return Ok(i);
        }
        if depth > 64 {
            return Err(Error::MsgDef {
                type_name: name.to_string(),
                line: 0,
                message: "message types nest more than 64 deep (recursive definition?)".into(),
            });
        }
        let raw_type = match index.get(name) {
            Some(&i) => &raw[i],
            None => {
                let Some(text) = builtin_definition(name) else {
                    return Err(Error::MsgDef {
                        type_name: name.to_string(),
                        line: 0,
                        message: "type is used but its definition (`MSG: …` section) is missing \
                                  from the schema text"
                            .into(),
                    });
                };
                // Built-ins have primitive fields only, so the parsed root is self-contained.
                let parsed = MsgDefs::parse(name, text)?;
                let slot = self.types.len();
                self.types.push(parsed.types[0].clone());
                resolved.insert(name.to_string(), slot);
                return Ok(slot);
            }
        };
        let slot = self.types.len();
        self.types.push(MsgType { name: name.to_string(), fields: Vec::new() });
        resolved.insert(name.to_string(), slot);
        let package = name.split('/').next().unwrap_or_default().to_string();
        let mut fields = Vec::with_capacity(raw_type.fields.len());
        for f in &raw_type.fields {
            let err = |message: String| Error::MsgDef { type_name: name.to_string(), line: f.line, message };
            let (base, arity) = split_array(&f.type_text).map_err(err)?;
            let ty = match Primitive::parse(base) {
                Some(p) => FieldType::Primitive(p),
                None => {
                    let full = match base {
                        "time" => "builtin_interfaces/msg/Time".to_string(),
                        "duration" => "builtin_interfaces/msg/Duration".to_string(),
                        "Header" => "std_msgs/msg/Header".to_string(),
                        b if b.contains('/') => normalize_type_name(b),
                        b => {
                            let local = format!("{package}/msg/{b}");
                            if index.contains_key(&local) {
                                local
                            } else {
                                // Fall back to any definition with that short name.
                                index.keys().find(|k| k.rsplit('/').next() == Some(b)).cloned().unwrap_or(local)
                            }
                        }
                    };
                    FieldType::Message(self.resolve(&full, raw, index, resolved, depth + 1)?)
                }
            };
            fields.push(Field { name: f.name.clone(), ty, arity, default: f.default.clone() });
        }
        self.types[slot].fields = fields;
        Ok(slot)
    }

    /// The root type.
    pub fn root(&self) -> &MsgType {
        &self.types[0]
    }

    /// A canonical one-line layout of the root type (field types and names, nested types
    /// expanded), used to check that a file's definition matches a typed fast path.
    pub fn layout(&self) -> String {
        let mut s = String::new();
        self.layout_of(0, &mut s);
        s
    }

    fn layout_of(&self, t: usize, out: &mut String) {
        out.push('{');
        for f in &self.types[t].fields {
            match &f.ty {
                FieldType::Primitive(p) => out.push_str(p.name()),
                FieldType::Message(i) => self.layout_of(*i, out),
            }
            match f.arity {
                Arity::Single => {}
                Arity::Fixed(n) => out.push_str(&format!("[{n}]")),
                Arity::Sequence { .. } => out.push_str("[]"),
            }
            out.push(' ');
            out.push_str(&f.name);
            out.push(';');
        }
        out.push('}');
    }
}

fn current_name(current: &RawType, root: &str) -> String {
    if current.name.is_empty() { root.to_string() } else { current.name.clone() }
}

/// Removes a `#` comment, leaving `#` inside quoted default strings alone.
fn strip_comment(line: &str) -> &str {
    let mut quote: Option<char> = None;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (None, '#') => return line[..i].trim(),
            (None, '"' | '\'') => quote = Some(c),
            (Some(q), c) if c == q => quote = None,
            _ => {}
        }
    }
    line.trim()
}

fn split_array(type_text: &str) -> std::result::Result<(&str, Arity), String> {
    let Some(open) = type_text.find('[') else {
        return Ok((type_text, Arity::Single));
    };
    let base = &type_text[..open];
    let inner = type_text[open + 1..]
        .strip_suffix(']')
        .ok_or_else(|| format!("array type `{type_text}` has no closing `]`"))?;
    let arity = if inner.is_empty() {
        Arity::Sequence { bound: None }
    } else if let Some(bound) = inner.strip_prefix("<=") {
        Arity::Sequence { bound: Some(bound.parse().map_err(|_| format!("bad array bound in `{type_text}`"))?) }
    } else {
        Arity::Fixed(inner.parse().map_err(|_| format!("bad array length in `{type_text}`"))?)
    };
    Ok((base, arity))
}

#[cfg(test)]
mod tests {
    use super::*;

    const JOINT_STATE: &str = "std_msgs/Header header\nstring[] name\nfloat64[] position\n\
        float64[] velocity\nfloat64[] effort\n\
        ================================================================================\n\
        MSG: std_msgs/Header\n# comment\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
        ================================================================================\n\
        MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";

    #[test]
    fn parses_joint_state_with_dependencies() {
        let d = MsgDefs::parse("sensor_msgs/msg/JointState", JOINT_STATE).unwrap();
        assert_eq!(d.root().name, "sensor_msgs/msg/JointState");
        assert_eq!(d.root().fields.len(), 5);
        assert_eq!(
            d.layout(),
            "{{{int32 sec;uint32 nanosec;} stamp;string frame_id;} header;string[] name;\
             float64[] position;float64[] velocity;float64[] effort;}"
        );
    }

    #[test]
    fn constants_are_skipped_and_defaults_kept() {
        let text = "uint8 A=1\nstring B = \"x # y\"  # comment\nint32[3] fixed\n\
                    string<=10[<=4] bounded\nfloat64 x 1.5\nint8 LOW= -1\n";
        let d = MsgDefs::parse("p/T", text).unwrap();
        let f = &d.root().fields;
        assert_eq!(f.len(), 3);
        assert_eq!(f[0].arity, Arity::Fixed(3));
        assert_eq!(f[1].arity, Arity::Sequence { bound: Some(4) });
        assert_eq!(f[1].ty, FieldType::Primitive(Primitive::String));
        assert_eq!(f[2].default.as_deref(), Some("1.5"));
    }

    #[test]
    fn missing_dependency_is_an_error_naming_it() {
        let err = MsgDefs::parse("p/T", "other_pkg/Thing t\n").unwrap_err();
        let text = err.to_string();
        assert!(text.contains("other_pkg/msg/Thing"), "{text}");
    }

    #[test]
    fn short_names_resolve_in_the_same_package() {
        let text = "Vector3 force\n====\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";
        let d = MsgDefs::parse("geometry_msgs/msg/Wrench", text).unwrap();
        assert_eq!(d.layout(), "{{float64 x;float64 y;float64 z;} force;}");
    }
}
