//! Reader for the parts of a CalculiX (Abaqus-style) input deck the import needs: `*NODE`,
//! `*ELEMENT`, `*NSET`, `*ELSET` (both with `GENERATE`), `*INCLUDE`, and rigtwin's metadata
//! comments (`** rigtwin clearance|pair|sensor ...`). Every other keyword and its data lines
//! are skipped.
//!
//! Syntax handled: keywords, parameters and set names are case-insensitive (names are
//! upper-cased as ccx does); `**` starts a comment; blank lines are ignored; a keyword line
//! ending with a comma continues on the next line; element data lines continue until the
//! element has all its nodes; `*INCLUDE` inserts a file in place (its data lines may continue
//! the block that was open), resolved relative to the including file, then to the working
//! directory. Nodes and elements must be defined before a set or element refers to them.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use super::matrix::read_text;
use super::{parse_real, CalculixError};

/// Where something was written.
#[derive(Clone, Debug)]
pub(crate) struct Loc {
    pub path: PathBuf,
    pub line: usize,
}

/// An element: its CalculiX type (upper case) and node numbers.
#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub kind: String,
    pub nodes: Vec<usize>,
}

impl Element {
    /// Continuum (solid) element, counted in `FeModel::n_elements`.
    pub fn is_solid(&self) -> bool {
        self.kind.starts_with("C3D")
    }
}

/// A node set: members in the order written (duplicates kept) and its definition order.
#[derive(Clone, Debug)]
pub(crate) struct NodeSet {
    pub members: Vec<usize>,
    /// Rank of the first definition among all node sets.
    pub order: usize,
}

/// `** rigtwin pair <lower> <upper> area <A> n <x y z> t1 <x y z>`.
#[derive(Clone, Debug)]
pub(crate) struct PairMeta {
    pub area: f64,
    pub normal: [f64; 3],
    pub t1: [f64; 3],
    pub at: Loc,
}

/// `** rigtwin sensor <name> dir <x y z>`.
#[derive(Clone, Debug)]
pub(crate) struct SensorMeta {
    pub name: String,
    pub direction: [f64; 3],
    pub at: Loc,
}

/// Metadata from `** rigtwin` comments.
#[derive(Clone, Debug, Default)]
pub(crate) struct Meta {
    pub clearance: Option<f64>,
    /// Keyed by (lower node, upper node), CalculiX numbers.
    pub pairs: HashMap<(usize, usize), PairMeta>,
    pub sensors: Vec<SensorMeta>,
}

/// What the import needs from a deck.
#[derive(Clone, Debug, Default)]
pub(crate) struct Deck {
    pub nodes: BTreeMap<usize, [f64; 3]>,
    pub elements: BTreeMap<usize, Element>,
    pub node_sets: BTreeMap<String, NodeSet>,
    pub element_sets: BTreeMap<String, Vec<usize>>,
    pub meta: Meta,
}

/// Reads a deck and the files it includes.
pub(crate) fn read_deck(path: &Path) -> Result<Deck, CalculixError> {
    let mut reader = Reader {
        stack: vec![Source::open(path)?],
    };
    let mut deck = Deck::default();
    let mut block = Block::Skip;
    while let Some((loc, text)) = reader.next_line() {
        let t = text.trim();
        if t.is_empty() {
            continue;
        }
        if let Some(comment) = t.strip_prefix("**") {
            parse_meta(comment, &loc, &mut deck.meta)?;
            continue;
        }
        if t.starts_with('*') {
            let mut keyword = t.to_string();
            while keyword.ends_with(',') {
                match reader.next_line() {
                    Some((_, more)) if more.trim().starts_with("**") => {}
                    Some((_, more)) => keyword.push_str(more.trim()),
                    None => {
                        return Err(CalculixError::parse(
                            &loc.path,
                            loc.line,
                            "the continuation of this keyword line",
                            "the end of the file",
                        ))
                    }
                }
            }
            let kw = Keyword::parse(&keyword);
            if kw.name == "INCLUDE" {
                let input = kw.param("INPUT").ok_or_else(|| {
                    CalculixError::parse(&loc.path, loc.line, "*INCLUDE,INPUT=<file>", t)
                })?;
                reader.include(input.trim_matches(['"', '\'']), &loc)?;
                continue;
            }
            block.finish()?;
            block = Block::start(&kw, &loc, &mut deck)?;
            continue;
        }
        block.data(t, &loc, &mut deck)?;
    }
    block.finish()?;
    Ok(deck)
}

/// A file being read.
struct Source {
    path: PathBuf,
    lines: Vec<String>,
    next: usize,
}

impl Source {
    fn open(path: &Path) -> Result<Self, CalculixError> {
        let text = read_text(path)?;
        Ok(Source {
            path: path.to_path_buf(),
            lines: text.lines().map(str::to_string).collect(),
            next: 0,
        })
    }
}

/// Line stream over the deck and its `*INCLUDE`s.
struct Reader {
    stack: Vec<Source>,
}

const MAX_INCLUDE_DEPTH: usize = 16;

impl Reader {
    fn next_line(&mut self) -> Option<(Loc, String)> {
        loop {
            let top = self.stack.last_mut()?;
            if top.next < top.lines.len() {
                top.next += 1;
                let text = std::mem::take(&mut top.lines[top.next - 1]);
                return Some((
                    Loc {
                        path: top.path.clone(),
                        line: top.next,
                    },
                    text,
                ));
            }
            self.stack.pop();
        }
    }

    fn include(&mut self, input: &str, at: &Loc) -> Result<(), CalculixError> {
        if self.stack.len() > MAX_INCLUDE_DEPTH {
            return Err(CalculixError::parse(
                &at.path,
                at.line,
                format!(
                    "*INCLUDE nesting of at most {MAX_INCLUDE_DEPTH} files (is there a cycle?)"
                ),
                input,
            ));
        }
        let given = Path::new(input);
        let beside = at
            .path
            .parent()
            .map(|d| d.join(given))
            .unwrap_or_else(|| given.to_path_buf());
        let chosen = if beside.is_file() {
            beside
        } else if given.is_file() {
            given.to_path_buf()
        } else {
            return Err(CalculixError::parse(
                &at.path,
                at.line,
                "an *INCLUDE file that exists (relative to this deck or the working directory)",
                input,
            ));
        };
        self.stack.push(Source::open(&chosen)?);
        Ok(())
    }
}

/// A keyword line split into name and parameters (upper-cased keys).
struct Keyword {
    name: String,
    params: Vec<(String, String)>,
}

impl Keyword {
    fn parse(line: &str) -> Self {
        let mut parts = line.trim_start_matches('*').split(',');
        let name = parts
            .next()
            .unwrap_or("")
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
            .to_uppercase();
        let params = parts
            .filter(|p| !p.trim().is_empty())
            .map(|p| match p.split_once('=') {
                Some((k, v)) => (k.trim().to_uppercase(), v.trim().to_string()),
                None => (p.trim().to_uppercase(), String::new()),
            })
            .collect();
        Keyword { name, params }
    }

    fn param(&self, key: &str) -> Option<&str> {
        self.params
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    fn flag(&self, key: &str) -> bool {
        self.params.iter().any(|(k, _)| k == key)
    }
}

/// The data block currently open.
enum Block {
    Skip,
    Node {
        nset: Option<String>,
    },
    Element {
        kind: String,
        n_nodes: usize,
        elset: Option<String>,
        pending: Vec<usize>,
        started: Option<Loc>,
    },
    Nset {
        name: String,
        generate: bool,
    },
    Elset {
        name: String,
        generate: bool,
    },
}

/// Nodes per element for the CalculiX element types.
fn nodes_per_element(kind: &str) -> Option<usize> {
    Some(match kind {
        "C3D4" | "S4" | "S4R" | "CPS4" | "CPS4R" | "CPE4" | "CPE4R" | "CAX4" | "CAX4R" => 4,
        "C3D6" | "S6" | "CPS6" | "CPE6" | "CAX6" => 6,
        "C3D8" | "C3D8R" | "C3D8I" | "S8" | "S8R" | "CPS8" | "CPS8R" | "CPE8" | "CPE8R"
        | "CAX8" | "CAX8R" => 8,
        "C3D10" | "C3D10T" => 10,
        "C3D15" => 15,
        "C3D20" | "C3D20R" => 20,
        "S3" | "CPS3" | "CPE3" | "CAX3" | "B32" | "B32R" | "T3D3" => 3,
        "B31" | "B31R" | "T3D2" | "SPRING2" | "SPRINGA" | "DASHPOTA" | "GAPUNI" => 2,
        "SPRING1" | "MASS" | "DCOUP3D" => 1,
        _ => return None,
    })
}

fn set_name(kw: &Keyword, key: &str, loc: &Loc) -> Result<String, CalculixError> {
    match kw.param(key) {
        Some(v) if !v.is_empty() => Ok(v.to_uppercase()),
        _ => Err(CalculixError::parse(
            &loc.path,
            loc.line,
            format!("*{},{key}=<name>", kw.name),
            format!("*{}", kw.name),
        )),
    }
}

/// Comma-separated fields of a data line, trimmed, without empty trailing fields.
fn fields(line: &str) -> Vec<&str> {
    let mut f: Vec<&str> = line.split(',').map(str::trim).collect();
    while f.last().is_some_and(|s| s.is_empty()) {
        f.pop();
    }
    f
}

fn int(field: &str, loc: &Loc, expected: &str) -> Result<usize, CalculixError> {
    match field.parse::<usize>() {
        Ok(v) if v >= 1 => Ok(v),
        _ => Err(CalculixError::parse(&loc.path, loc.line, expected, field)),
    }
}

/// `start, end[, step]` of a GENERATE line.
/// `start, end[, step]` of a GENERATE line; `largest` is the largest defined number, so an
/// absurd range fails before it is expanded.
fn generate(
    f: &[&str],
    loc: &Loc,
    largest: usize,
    context: String,
    what: &'static str,
) -> Result<Vec<usize>, CalculixError> {
    let expected = "`start, end[, step]` with 1 <= start <= end and step >= 1";
    if !(2..=3).contains(&f.len()) {
        return Err(CalculixError::parse(
            &loc.path,
            loc.line,
            expected,
            f.join(","),
        ));
    }
    let a = int(f[0], loc, expected)?;
    let b = int(f[1], loc, expected)?;
    let step = if f.len() == 3 {
        int(f[2], loc, expected)?
    } else {
        1
    };
    if b > largest {
        return Err(CalculixError::UnknownNode {
            path: loc.path.clone(),
            line: loc.line,
            context,
            what,
            id: b,
        });
    }
    if a > b {
        return Err(CalculixError::parse(
            &loc.path,
            loc.line,
            expected,
            f.join(","),
        ));
    }
    Ok((a..=b).step_by(step).collect())
}

impl Block {
    fn start(kw: &Keyword, loc: &Loc, deck: &mut Deck) -> Result<Block, CalculixError> {
        Ok(match kw.name.as_str() {
            "NODE" => {
                let nset = kw.param("NSET").map(str::to_uppercase);
                if let Some(name) = &nset {
                    ensure_node_set(deck, name);
                }
                Block::Node { nset }
            }
            "ELEMENT" => {
                let kind = kw.param("TYPE").unwrap_or("").to_uppercase();
                let n_nodes = nodes_per_element(&kind).ok_or_else(|| {
                    CalculixError::parse(
                        &loc.path,
                        loc.line,
                        "*ELEMENT,TYPE=<a known type: C3D8, C3D8I, C3D20, SPRING2, MASS, ...>",
                        kind.clone(),
                    )
                })?;
                let elset = kw.param("ELSET").map(str::to_uppercase);
                if let Some(name) = &elset {
                    deck.element_sets.entry(name.clone()).or_default();
                }
                Block::Element {
                    kind,
                    n_nodes,
                    elset,
                    pending: Vec::new(),
                    started: None,
                }
            }
            "NSET" => {
                let name = set_name(kw, "NSET", loc)?;
                ensure_node_set(deck, &name);
                Block::Nset {
                    name,
                    generate: kw.flag("GENERATE"),
                }
            }
            "ELSET" => {
                let name = set_name(kw, "ELSET", loc)?;
                deck.element_sets.entry(name.clone()).or_default();
                Block::Elset {
                    name,
                    generate: kw.flag("GENERATE"),
                }
            }
            _ => Block::Skip,
        })
    }

    fn data(&mut self, line: &str, loc: &Loc, deck: &mut Deck) -> Result<(), CalculixError> {
        match self {
            Block::Skip => {}
            Block::Node { nset } => {
                let f = fields(line);
                let expected = "a node line `number, x, y, z`";
                if f.is_empty() || f.len() > 4 {
                    return Err(CalculixError::parse(&loc.path, loc.line, expected, line));
                }
                let id = int(f[0], loc, "a node number >= 1")?;
                let mut x = [0.0; 3];
                for (c, s) in f[1..].iter().enumerate() {
                    x[c] = parse_real(s).ok_or_else(|| {
                        CalculixError::parse(&loc.path, loc.line, "a finite real coordinate", *s)
                    })?;
                }
                if deck.nodes.insert(id, x).is_some() {
                    return Err(CalculixError::parse(
                        &loc.path,
                        loc.line,
                        "each node number defined once",
                        format!("node {id} again"),
                    ));
                }
                if let Some(name) = nset {
                    push_node(deck, name, id);
                }
            }
            Block::Element {
                kind,
                n_nodes,
                elset,
                pending,
                started,
            } => {
                if started.is_none() {
                    *started = Some(loc.clone());
                }
                for s in fields(line) {
                    pending.push(int(s, loc, "an element or node number >= 1")?);
                }
                if pending.len() > *n_nodes + 1 {
                    return Err(CalculixError::parse(
                        &loc.path,
                        loc.line,
                        format!("an element number and {n_nodes} node numbers for a {kind}"),
                        line,
                    ));
                }
                if pending.len() == *n_nodes + 1 {
                    let id = pending[0];
                    let context = format!("element {id}");
                    for &n in &pending[1..] {
                        if !deck.nodes.contains_key(&n) {
                            return Err(CalculixError::UnknownNode {
                                path: loc.path.clone(),
                                line: loc.line,
                                context,
                                what: "node",
                                id: n,
                            });
                        }
                    }
                    let el = Element {
                        kind: kind.clone(),
                        nodes: pending[1..].to_vec(),
                    };
                    if deck.elements.insert(id, el).is_some() {
                        return Err(CalculixError::parse(
                            &loc.path,
                            loc.line,
                            "each element number defined once",
                            format!("element {id} again"),
                        ));
                    }
                    if let Some(name) = elset {
                        deck.element_sets.entry(name.clone()).or_default().push(id);
                    }
                    pending.clear();
                    *started = None;
                }
            }
            Block::Nset { name, generate: g } => {
                let f = fields(line);
                let ids = if *g {
                    let largest = deck.nodes.keys().next_back().copied().unwrap_or(0);
                    generate(&f, loc, largest, format!("node set {name}"), "node")?
                } else {
                    let mut ids = Vec::new();
                    for s in f.into_iter().filter(|s| !s.is_empty()) {
                        if s.bytes().all(|b| b.is_ascii_digit()) {
                            ids.push(int(s, loc, "a node number >= 1")?);
                        } else {
                            let other = s.to_uppercase();
                            let members = deck.node_sets.get(&other).ok_or_else(|| {
                                CalculixError::MissingSet {
                                    path: loc.path.clone(),
                                    name: other.clone(),
                                    needed_for: format!(
                                        "line {} adds it to node set {name}",
                                        loc.line
                                    ),
                                }
                            })?;
                            ids.extend_from_slice(&members.members);
                        }
                    }
                    ids
                };
                for id in ids {
                    if !deck.nodes.contains_key(&id) {
                        return Err(CalculixError::UnknownNode {
                            path: loc.path.clone(),
                            line: loc.line,
                            context: format!("node set {name}"),
                            what: "node",
                            id,
                        });
                    }
                    push_node(deck, name, id);
                }
            }
            Block::Elset { name, generate: g } => {
                let f = fields(line);
                let ids = if *g {
                    let largest = deck.elements.keys().next_back().copied().unwrap_or(0);
                    generate(&f, loc, largest, format!("element set {name}"), "element")?
                } else {
                    let mut ids = Vec::new();
                    for s in f.into_iter().filter(|s| !s.is_empty()) {
                        if s.bytes().all(|b| b.is_ascii_digit()) {
                            ids.push(int(s, loc, "an element number >= 1")?);
                        } else {
                            let other = s.to_uppercase();
                            let members = deck.element_sets.get(&other).ok_or_else(|| {
                                CalculixError::MissingSet {
                                    path: loc.path.clone(),
                                    name: other.clone(),
                                    needed_for: format!(
                                        "line {} adds it to element set {name}",
                                        loc.line
                                    ),
                                }
                            })?;
                            ids.extend_from_slice(members);
                        }
                    }
                    ids
                };
                for id in ids {
                    if !deck.elements.contains_key(&id) {
                        return Err(CalculixError::UnknownNode {
                            path: loc.path.clone(),
                            line: loc.line,
                            context: format!("element set {name}"),
                            what: "element",
                            id,
                        });
                    }
                    deck.element_sets.entry(name.clone()).or_default().push(id);
                }
            }
        }
        Ok(())
    }

    /// Closes the block; an element with missing nodes is an error.
    fn finish(&self) -> Result<(), CalculixError> {
        if let Block::Element {
            kind,
            n_nodes,
            pending,
            started: Some(start),
            ..
        } = self
        {
            if !pending.is_empty() {
                return Err(CalculixError::parse(
                    &start.path,
                    start.line,
                    format!(
                        "an element number and {n_nodes} node numbers for a {kind} (data lines \
                         may continue on the next lines)"
                    ),
                    format!(
                        "{} number(s) before the next keyword or the end of the input",
                        pending.len()
                    ),
                ));
            }
        }
        Ok(())
    }
}

fn ensure_node_set(deck: &mut Deck, name: &str) {
    let order = deck.node_sets.len();
    deck.node_sets
        .entry(name.to_string())
        .or_insert_with(|| NodeSet {
            members: Vec::new(),
            order,
        });
}

fn push_node(deck: &mut Deck, name: &str, id: usize) {
    ensure_node_set(deck, name);
    if let Some(set) = deck.node_sets.get_mut(name) {
        set.members.push(id);
    }
}

/// Interprets `** rigtwin <key> ...`; other comments are ignored.
fn parse_meta(comment: &str, loc: &Loc, meta: &mut Meta) -> Result<(), CalculixError> {
    let tokens: Vec<&str> = comment.split_whitespace().collect();
    if tokens.first().map(|s| s.to_lowercase()) != Some("rigtwin".into()) {
        return Ok(());
    }
    let bad = |expected: &str| {
        CalculixError::parse(&loc.path, loc.line, expected, format!("**{comment}"))
    };
    let real = |s: &str, expected: &str| parse_real(s).ok_or_else(|| bad(expected));
    let vec3 = |t: &[&str], expected: &str| -> Result<[f64; 3], CalculixError> {
        Ok([
            real(t[0], expected)?,
            real(t[1], expected)?,
            real(t[2], expected)?,
        ])
    };
    match tokens.get(1).map(|s| s.to_lowercase()).as_deref() {
        Some("clearance") => {
            let expected = "`** rigtwin clearance <metres>`";
            if tokens.len() != 3 {
                return Err(bad(expected));
            }
            meta.clearance = Some(real(tokens[2], expected)?);
        }
        Some("pair") => {
            let expected =
                "`** rigtwin pair <lower node> <upper node> area <m^2> n <x y z> t1 <x y z>`";
            if tokens.len() != 14
                || !tokens[4].eq_ignore_ascii_case("area")
                || !tokens[6].eq_ignore_ascii_case("n")
                || !tokens[10].eq_ignore_ascii_case("t1")
            {
                return Err(bad(expected));
            }
            let lower: usize = tokens[2].parse().map_err(|_| bad(expected))?;
            let upper: usize = tokens[3].parse().map_err(|_| bad(expected))?;
            let pair = PairMeta {
                area: real(tokens[5], expected)?,
                normal: vec3(&tokens[7..10], expected)?,
                t1: vec3(&tokens[11..14], expected)?,
                at: loc.clone(),
            };
            meta.pairs.insert((lower, upper), pair);
        }
        Some("sensor") => {
            let expected = "`** rigtwin sensor <name> dir <x y z>`";
            if tokens.len() != 7 || !tokens[3].eq_ignore_ascii_case("dir") {
                return Err(bad(expected));
            }
            let direction = vec3(&tokens[4..7], expected)?;
            meta.sensors.push(SensorMeta {
                name: tokens[2].to_string(),
                direction,
                at: loc.clone(),
            });
        }
        _ => {}
    }
    Ok(())
}
