//! Mitsuba scene XML as an owned element tree, with the file-level features of Mitsuba 3
//! resolved before the scene is read:
//!
//! - `<include filename="…"/>` splices the children of the named file's `<scene>` in its
//!   place. The file goes through [`files::resolve_reference`] like every other reference
//!   (contained in the scene's folder unless external paths are allowed), looked for first
//!   beside the file that includes it, then in the scene file's folder (Mitsuba's search
//!   path). Includes nest at most [`MAX_INCLUDE_DEPTH`] deep; a file that includes itself,
//!   directly or not, is an error naming the chain.
//! - `<default name="n" value="v"/>` defines the parameter `n` unless it is already defined
//!   (by an override passed to the reader, or an earlier `<default>`), and `$n` in any later
//!   attribute value is replaced by its value. A `$name` with no definition is an error naming
//!   it, the file and the line. A `$` not followed by a name is kept as written.
//!
//! Every element remembers the file and line it was written at, so errors inside an included
//! file name that file.

use super::files::{self, ReadPolicy};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Deepest chain of `<include>`s followed.
pub const MAX_INCLUDE_DEPTH: usize = 16;
/// Most XML nodes one file may hold (roxmltree's own limit).
const MAX_XML_NODES: u32 = 1_000_000;
/// Most elements the scene may hold with its includes spliced in (a file included many times
/// counts each time).
pub const MAX_ELEMENTS: usize = 1_000_000;

/// A file the tree was read from: its name for messages and the folder its references resolve
/// against (`None`: bytes without a file; references cannot be resolved).
#[derive(Clone, Debug)]
pub struct Source {
    pub display: String,
    pub base_dir: Option<PathBuf>,
}

/// An XML element with its parameters substituted.
#[derive(Clone, Debug)]
pub struct Element {
    tag: String,
    attributes: Vec<(String, String)>,
    children: Vec<Element>,
    /// Index of the file it was written in, in [`Document::sources`] (0: the scene file).
    pub source: usize,
    /// 1-based line of its start tag.
    pub line: u32,
}

impl Element {
    pub fn tag(&self) -> &str {
        &self.tag
    }

    pub fn attribute(&self, name: &str) -> Option<&str> {
        self.attributes
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    pub fn children(&self) -> std::slice::Iter<'_, Element> {
        self.children.iter()
    }
}

/// A scene file read with its includes.
#[derive(Debug)]
pub struct Document {
    /// The `<scene>` element.
    pub root: Element,
    /// The scene file first, then each included file in the order it was read.
    pub sources: Vec<Source>,
}

impl Document {
    /// Where `element` was written: "line N" in the scene file, "FILE line N" in an included
    /// one.
    pub fn at(&self, element: &Element) -> String {
        if element.source == 0 {
            format!("line {}", element.line)
        } else {
            format!(
                "{} line {}",
                self.sources[element.source].display, element.line
            )
        }
    }

    /// Resolves a file reference written in `element` (a mesh, a texture): beside the file
    /// that names it first, then in the scene file's folder. The error is the problem alone.
    pub fn resolve(
        &self,
        element: &Element,
        reference: &str,
        kind: &str,
        policy: ReadPolicy,
    ) -> Result<PathBuf, String> {
        resolve_in(&self.sources, element.source, reference, kind, policy)
    }
}

/// [`Document::resolve`] for the file `source` of `sources`.
fn resolve_in(
    sources: &[Source],
    source: usize,
    reference: &str,
    kind: &str,
    policy: ReadPolicy,
) -> Result<PathBuf, String> {
    let Some(scene_dir) = sources[0].base_dir.as_deref() else {
        return Err(format!(
            "{kind} '{reference}' cannot be read: the scene was given without a folder"
        ));
    };
    let mut folders: Vec<&Path> = Vec::with_capacity(2);
    for index in [source, 0] {
        if let Some(dir) = sources[index].base_dir.as_deref() {
            if !folders.contains(&dir) {
                folders.push(dir);
            }
        }
    }
    let mut result = Err(String::new());
    for folder in folders {
        result = files::resolve_reference_within(folder, scene_dir, reference, kind, policy);
        match &result {
            Err(m) if m.starts_with("missing") => continue,
            _ => break,
        }
    }
    result
}

/// Reads a scene file's bytes into a [`Document`]. `top_file` is the scene file's canonical
/// path when known (so that an include of it is reported as a cycle at once); `overrides`
/// define parameters ahead of the file's `<default>`s. The error is the message alone.
pub fn read(
    bytes: &[u8],
    display: &str,
    base_dir: Option<&Path>,
    top_file: Option<PathBuf>,
    policy: ReadPolicy,
    overrides: &[(String, String)],
) -> Result<Document, String> {
    let mut reader = TreeReader {
        sources: vec![Source {
            display: display.to_string(),
            base_dir: base_dir.map(Path::to_path_buf),
        }],
        parameters: overrides.iter().cloned().collect(),
        chain: top_file.into_iter().collect(),
        policy,
        depth: 0,
        elements: 0,
    };
    let root = reader.read_file(bytes, 0)?;
    Ok(Document {
        root,
        sources: reader.sources,
    })
}

struct TreeReader {
    sources: Vec<Source>,
    parameters: HashMap<String, String>,
    /// Canonical paths of the files being read, outermost first (cycle detection); the scene
    /// file's own is missing when it was given as bytes.
    chain: Vec<PathBuf>,
    /// Includes being followed, nested.
    depth: usize,
    policy: ReadPolicy,
    elements: usize,
}

impl TreeReader {
    /// Parses the file `source` and returns its `<scene>` element, converted.
    fn read_file(&mut self, bytes: &[u8], source: usize) -> Result<Element, String> {
        let text = std::str::from_utf8(bytes).map_err(|e| format!("not UTF-8 text: {e}"))?;
        let options = roxmltree::ParsingOptions {
            allow_dtd: false,
            nodes_limit: MAX_XML_NODES,
            ..Default::default()
        };
        let document = roxmltree::Document::parse_with_options(text, options)
            .map_err(|e| format!("malformed XML: {e}"))?;
        let root = document.root_element();
        if root.tag_name().name() != "scene" {
            return Err(format!(
                "root element is <{}>, not <scene> (not a Mitsuba scene)",
                root.tag_name().name()
            ));
        }
        let mut converted = self.convert(root, source)?;
        debug_assert_eq!(converted.len(), 1);
        Ok(converted.remove(0))
    }

    fn at(&self, node: roxmltree::Node, source: usize) -> String {
        let line = node.document().text_pos_at(node.range().start).row;
        if source == 0 {
            format!("line {line}")
        } else {
            format!("{} line {line}", self.sources[source].display)
        }
    }

    /// The element `node` with its parameters substituted: one element, or for an
    /// `<include>` the included scene's children, or none for a `<default>`.
    fn convert(&mut self, node: roxmltree::Node, source: usize) -> Result<Vec<Element>, String> {
        self.elements += 1;
        if self.elements > MAX_ELEMENTS {
            return Err(format!(
                "{}: the scene and its includes hold more than {MAX_ELEMENTS} elements",
                self.at(node, source)
            ));
        }
        let mut attributes = Vec::new();
        for attribute in node.attributes() {
            let value = self
                .substitute(attribute.value())
                .map_err(|m| format!("{}: {m}", self.at(node, source)))?;
            attributes.push((attribute.name().to_string(), value));
        }
        let get = |name: &str| {
            attributes
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, v)| v.clone())
        };
        match node.tag_name().name() {
            "default" => {
                let (Some(name), Some(value)) = (get("name"), get("value")) else {
                    return Err(format!(
                        "{}: <default> needs a name and a value",
                        self.at(node, source)
                    ));
                };
                if !is_parameter_name(&name) {
                    return Err(format!(
                        "{}: <default> name '{name}' is not a parameter name (letters, digits, _)",
                        self.at(node, source)
                    ));
                }
                // Overrides and earlier defaults win.
                self.parameters.entry(name).or_insert(value);
                return Ok(Vec::new());
            }
            "include" => {
                let file = get("filename").unwrap_or_default();
                return self
                    .include(&file, source)
                    .map_err(|m| format!("{}: include '{file}': {m}", self.at(node, source)));
            }
            _ => {}
        }
        let mut children = Vec::new();
        for child in node.children().filter(roxmltree::Node::is_element) {
            children.extend(self.convert(child, source)?);
        }
        Ok(vec![Element {
            tag: node.tag_name().name().to_string(),
            attributes,
            children,
            source,
            line: node.document().text_pos_at(node.range().start).row,
        }])
    }

    /// The children of the included file's `<scene>`.
    fn include(&mut self, file: &str, from: usize) -> Result<Vec<Element>, String> {
        if self.depth == MAX_INCLUDE_DEPTH {
            return Err(format!(
                "includes nest deeper than {MAX_INCLUDE_DEPTH} files"
            ));
        }
        let path = resolve_in(&self.sources, from, file, "include", self.policy)?;
        if let Some(first) = self.chain.iter().position(|p| *p == path) {
            let names: Vec<String> = self.chain[first..]
                .iter()
                .chain(std::iter::once(&path))
                .map(|p| self.shown(p))
                .collect();
            return Err(format!("include cycle: {}", names.join(" → ")));
        }
        let bytes = files::read_regular_file(&path)?;
        self.sources.push(Source {
            display: self.shown(&path),
            base_dir: path.parent().map(Path::to_path_buf),
        });
        let source = self.sources.len() - 1;
        self.chain.push(path);
        self.depth += 1;
        let scene = self.read_file(&bytes, source);
        self.depth -= 1;
        self.chain.pop();
        Ok(scene?.children)
    }

    /// `path` relative to the scene file's folder when inside it (as the scene names it),
    /// else in full.
    fn shown(&self, path: &Path) -> String {
        let top = self.sources[0].base_dir.as_deref().and_then(|d| {
            std::fs::canonicalize(if d.as_os_str().is_empty() {
                Path::new(".")
            } else {
                d
            })
            .ok()
        });
        match top.as_deref().and_then(|t| path.strip_prefix(t).ok()) {
            Some(relative) => relative.display().to_string(),
            None => path.display().to_string(),
        }
    }

    /// `value` with every `$name` replaced by its parameter.
    fn substitute(&self, value: &str) -> Result<String, String> {
        if !value.contains('$') {
            return Ok(value.to_string());
        }
        let mut out = String::with_capacity(value.len());
        let mut rest = value;
        while let Some(dollar) = rest.find('$') {
            out.push_str(&rest[..dollar]);
            let after = &rest[dollar + 1..];
            let end = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            let name = &after[..end];
            if name.is_empty() {
                out.push('$');
            } else {
                match self.parameters.get(name) {
                    Some(v) => out.push_str(v),
                    None => {
                        return Err(format!(
                            "parameter '${name}' is not defined (no <default name=\"{name}\"> \
                             before it)"
                        ))
                    }
                }
            }
            rest = &after[end..];
        }
        out.push_str(rest);
        Ok(out)
    }
}

fn is_parameter_name(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tree(xml: &str) -> Result<Document, String> {
        read(
            xml.as_bytes(),
            "s.xml",
            None,
            None,
            ReadPolicy::default(),
            &[],
        )
    }

    #[test]
    fn defaults_substitute_in_later_attributes() {
        let doc = tree(
            r#"<scene><default name="res" value="256"/><default name="res" value="9"/>
               <film width="$res" height="$res_h" label="$res px, 5$"/></scene>"#,
        );
        let err = doc.unwrap_err();
        assert!(
            err.contains("line 2") && err.contains("'$res_h' is not defined"),
            "{err}"
        );
        let doc = tree(
            r#"<scene><default name="res" value="256"/><default name="res" value="9"/>
               <film width="$res" label="$res px, 5$ $"/></scene>"#,
        )
        .unwrap();
        let film = doc.root.children().next().unwrap();
        // The first definition wins; a `$` without a name stays.
        assert_eq!(film.attribute("width"), Some("256"));
        assert_eq!(film.attribute("label"), Some("256 px, 5$ $"));
        assert_eq!(film.line, 2);
    }

    #[test]
    fn overrides_win_over_defaults() {
        let doc = read(
            br#"<scene><default name="spp" value="4"/><s v="$spp"/></scene>"#,
            "s.xml",
            None,
            None,
            ReadPolicy::default(),
            &[("spp".into(), "64".into())],
        )
        .unwrap();
        assert_eq!(
            doc.root.children().next().unwrap().attribute("v"),
            Some("64")
        );
    }

    #[test]
    fn an_undefined_parameter_before_its_default_is_an_error() {
        let err = tree(r#"<scene><s v="$a"/><default name="a" value="1"/></scene>"#).unwrap_err();
        assert!(err.contains("'$a' is not defined"), "{err}");
        let err = tree(r#"<scene><default name="a b" value="1"/></scene>"#).unwrap_err();
        assert!(err.contains("not a parameter name"), "{err}");
    }
}
