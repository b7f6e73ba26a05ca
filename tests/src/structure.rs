//! The workspace's structure rules, measured on the source (issue 18): no function outside
//! tests longer than [`MAX_FN_LINES`] lines, and no import cycle between the modules of a
//! crate. Run by `.ci/run` through the `structure-check` binary.
//!
//! Why a parser and not `grep`: a function's end is a matching brace, and `#[cfg(test)]`
//! modules, `#[test]` functions and nested functions need the syntax tree to be told apart.
//! `syn` parses the file as the compiler would (macro bodies stay opaque), and
//! `proc-macro2`'s `span-locations` gives the line of every token.
//!
//! **What is measured.** Every `fn` with a body (free functions, inherent and trait methods,
//! trait default methods, functions nested in other functions) in every `.rs` file under
//! the crates' folders, except: items under `#[cfg(test)]` (modules, impls, functions),
//! `#[test]` functions, and any folder named `tests`, `benches` or `target` (integration
//! tests, benchmarks, build output). A function's length is the number of lines from its
//! `fn` keyword to its closing brace, both included; its doc comment and attributes are not
//! counted. A nested function counts both alone and inside its outer function.
//!
//! **What an import is.** Within one crate's `src/` (binaries under `src/bin/` are crates of
//! their own and are left out), every `use` and every path in the code that starts with
//! `crate::`, `super::` or `self::` names a file module (the longest prefix of the path that
//! is a module file). Module A imports module B when such a path in A's file names B, where
//! neither is the other's ancestor (a parent is the namespace of its children: `pub use` of
//! a child and a child's use of what its parent re-exports are not dependencies between
//! parts). A cycle is a strongly connected component of more than one module in that graph.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use syn::visit::Visit;

/// The longest function allowed outside tests (issue 18): above it a function is to be split
/// into named stages.
pub const MAX_FN_LINES: usize = 150;

/// The crates whose sources are checked, as folders under the workspace root.
pub const CRATES: [&str; 5] = [
    "fsw-core",
    "gro-reference",
    "sim-harness",
    "ground-tool",
    "tests",
];

/// One function's measured length.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FnLength {
    /// File, relative to the workspace root.
    pub file: PathBuf,
    /// Line of the `fn` keyword.
    pub line: usize,
    /// `name`, or `Type::name` for a method.
    pub name: String,
    /// Lines from the `fn` keyword to the closing brace, both included.
    pub lines: usize,
}

/// A file that could not be read or parsed.
#[derive(Debug, thiserror::Error)]
pub enum StructureError {
    /// The file or folder could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not Rust that `syn` parses.
    #[error("cannot parse {path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parse error.
        source: syn::Error,
    },
}

/// True for `#[cfg(test)]` (and only that: `cfg(not(test))` code is built outside tests).
fn is_cfg_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.parse_args::<syn::Ident>()
                .map(|id| id == "test")
                .unwrap_or(false)
    })
}

/// True for a `#[test]` function.
fn is_test_fn(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| a.path().is_ident("test"))
}

/// The last identifier of a type's path (`Foo` of `crate::x::Foo<T>`), for method names.
fn type_name(ty: &syn::Type) -> String {
    match ty {
        syn::Type::Path(p) => p
            .path
            .segments
            .last()
            .map(|s| s.ident.to_string())
            .unwrap_or_default(),
        _ => "_".to_string(),
    }
}

/// Lines from `start` to `end`, both included.
fn span_lines(start: proc_macro2::Span, end: proc_macro2::Span) -> usize {
    end.end().line.saturating_sub(start.start().line) + 1
}

/// Walks one file's syntax tree and records every function outside tests.
struct FnCollector<'a> {
    file: &'a Path,
    owner: Vec<String>,
    found: Vec<FnLength>,
}

impl FnCollector<'_> {
    fn record(&mut self, name: &syn::Ident, sig: &syn::Signature, block: &syn::Block) {
        let name = match self.owner.last() {
            Some(owner) => format!("{owner}::{name}"),
            None => name.to_string(),
        };
        self.found.push(FnLength {
            file: self.file.to_path_buf(),
            line: sig.fn_token.span.start().line,
            name,
            lines: span_lines(sig.fn_token.span, block.brace_token.span.close()),
        });
    }

    /// A function (unless `skip`): recorded when it has a body, then its body walked by
    /// `walk` with no owner type (a nested function has none).
    fn function(
        &mut self,
        skip: bool,
        sig: &syn::Signature,
        block: Option<&syn::Block>,
        walk: impl FnOnce(&mut Self),
    ) {
        if skip {
            return;
        }
        if let Some(block) = block {
            self.record(&sig.ident, sig, block);
        }
        let owners = std::mem::take(&mut self.owner);
        walk(self);
        self.owner = owners;
    }

    /// An impl or trait (unless `skip`): its items walked by `walk` with `owner` as their
    /// owner type.
    fn owned(&mut self, skip: bool, owner: String, walk: impl FnOnce(&mut Self)) {
        if skip {
            return;
        }
        self.owner.push(owner);
        walk(self);
        self.owner.pop();
    }
}

impl<'ast> Visit<'ast> for FnCollector<'_> {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if !is_cfg_test(&m.attrs) {
            syn::visit::visit_item_mod(self, m);
        }
    }
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        let skip = is_cfg_test(&f.attrs) || is_test_fn(&f.attrs);
        self.function(skip, &f.sig, Some(&f.block), |c| {
            syn::visit::visit_item_fn(c, f);
        });
    }
    fn visit_item_impl(&mut self, i: &'ast syn::ItemImpl) {
        self.owned(is_cfg_test(&i.attrs), type_name(&i.self_ty), |c| {
            syn::visit::visit_item_impl(c, i);
        });
    }
    fn visit_item_trait(&mut self, t: &'ast syn::ItemTrait) {
        self.owned(is_cfg_test(&t.attrs), t.ident.to_string(), |c| {
            syn::visit::visit_item_trait(c, t);
        });
    }
    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        let skip = is_cfg_test(&f.attrs) || is_test_fn(&f.attrs);
        self.function(skip, &f.sig, Some(&f.block), |c| {
            syn::visit::visit_impl_item_fn(c, f);
        });
    }
    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        self.function(is_cfg_test(&f.attrs), &f.sig, f.default.as_ref(), |c| {
            syn::visit::visit_trait_item_fn(c, f);
        });
    }
}

/// Every function outside tests in one file's source (`file` names it in the result).
pub fn function_lengths(file: &Path, source: &str) -> Result<Vec<FnLength>, StructureError> {
    let ast = syn::parse_file(source).map_err(|source| StructureError::Parse {
        path: file.to_path_buf(),
        source,
    })?;
    let mut c = FnCollector {
        file,
        owner: Vec::new(),
        found: Vec::new(),
    };
    c.visit_file(&ast);
    Ok(c.found)
}

/// Every `.rs` file under `dir`, skipping folders named `tests`, `benches` and `target`,
/// sorted so the output is stable.
pub fn rust_files(dir: &Path) -> Result<Vec<PathBuf>, StructureError> {
    let mut out = Vec::new();
    let read = |p: &Path| {
        std::fs::read_dir(p).map_err(|source| StructureError::Read {
            path: p.to_path_buf(),
            source,
        })
    };
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in read(&d)? {
            let path = entry
                .map_err(|source| StructureError::Read {
                    path: d.clone(),
                    source,
                })?
                .path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() {
                if !matches!(name, "tests" | "benches" | "target") && !name.starts_with('.') {
                    stack.push(path);
                }
            } else if name.ends_with(".rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    Ok(out)
}

fn read_source(path: &Path) -> Result<String, StructureError> {
    std::fs::read_to_string(path).map_err(|source| StructureError::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// Every function outside tests in the checked crates under `root`, longest first (ties by
/// file and line).
pub fn workspace_function_lengths(root: &Path) -> Result<Vec<FnLength>, StructureError> {
    let mut all = Vec::new();
    for krate in CRATES {
        for path in rust_files(&root.join(krate))? {
            let rel = path.strip_prefix(root).unwrap_or(&path);
            all.extend(function_lengths(rel, &read_source(&path)?)?);
        }
    }
    all.sort_by(|a, b| {
        b.lines
            .cmp(&a.lines)
            .then_with(|| a.file.cmp(&b.file))
            .then(a.line.cmp(&b.line))
    });
    Ok(all)
}

/// A module path inside one crate (`["tables", "image"]`; empty for the crate root).
pub type ModPath = Vec<String>;

/// The module a file under `src/` defines (`a/mod.rs` and `a.rs` are `a`; `lib.rs` and
/// `main.rs` the root).
pub fn module_of(rel_to_src: &Path) -> ModPath {
    let mut parts: Vec<String> = rel_to_src
        .iter()
        .map(|s| s.to_string_lossy().into_owned())
        .collect();
    if let Some(last) = parts.pop() {
        let stem = last.trim_end_matches(".rs");
        if !matches!(stem, "mod" | "lib" | "main") {
            parts.push(stem.to_string());
        }
    }
    parts
}

/// Collects the module paths a file names through `crate::`, `super::` and `self::`.
struct ImportCollector {
    /// The module the code being walked is in (inline modules included).
    here: ModPath,
    /// Absolute paths named, as segment lists from the crate root.
    named: Vec<ModPath>,
}

impl ImportCollector {
    /// Resolves a path's leading `crate`/`super`/`self` segments against `here`; `None` for a
    /// path that starts elsewhere (another crate, a local name).
    fn absolute(&self, segments: &[String]) -> Option<ModPath> {
        let first = segments.first()?;
        let (mut base, mut rest) = match first.as_str() {
            "crate" => (Vec::new(), &segments[1..]),
            "self" => (self.here.clone(), &segments[1..]),
            "super" => (self.here.clone(), segments),
            _ => return None,
        };
        while let Some(s) = rest.first() {
            if s != "super" {
                break;
            }
            base.pop();
            rest = &rest[1..];
        }
        base.extend(rest.iter().cloned());
        Some(base)
    }

    fn use_tree(&mut self, prefix: &mut Vec<String>, tree: &syn::UseTree) {
        match tree {
            syn::UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                self.use_tree(prefix, &p.tree);
                prefix.pop();
            }
            syn::UseTree::Name(n) => {
                prefix.push(n.ident.to_string());
                self.push(prefix);
                prefix.pop();
            }
            syn::UseTree::Rename(r) => {
                prefix.push(r.ident.to_string());
                self.push(prefix);
                prefix.pop();
            }
            syn::UseTree::Glob(_) => self.push(prefix),
            syn::UseTree::Group(g) => {
                for t in &g.items {
                    self.use_tree(prefix, t);
                }
            }
        }
    }

    fn push(&mut self, segments: &[String]) {
        if let Some(abs) = self.absolute(segments) {
            self.named.push(abs);
        }
    }
}

impl<'ast> Visit<'ast> for ImportCollector {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if is_cfg_test(&m.attrs) {
            return;
        }
        self.here.push(m.ident.to_string());
        syn::visit::visit_item_mod(self, m);
        self.here.pop();
    }
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if !is_cfg_test(&f.attrs) && !is_test_fn(&f.attrs) {
            syn::visit::visit_item_fn(self, f);
        }
    }
    fn visit_item_impl(&mut self, i: &'ast syn::ItemImpl) {
        if !is_cfg_test(&i.attrs) {
            syn::visit::visit_item_impl(self, i);
        }
    }
    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        if !is_cfg_test(&u.attrs) {
            self.use_tree(&mut Vec::new(), &u.tree);
        }
    }
    fn visit_path(&mut self, p: &'ast syn::Path) {
        let segments: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
        self.push(&segments);
        syn::visit::visit_path(self, p);
    }
}

/// The module dependency graph of one crate: module → modules it imports (see the module
/// doc for the rule). `files` maps each file module to its source.
pub fn import_graph(
    files: &BTreeMap<ModPath, String>,
) -> Result<BTreeMap<ModPath, BTreeSet<ModPath>>, StructureError> {
    let mut graph = BTreeMap::new();
    for (module, source) in files {
        let ast = syn::parse_file(source).map_err(|source| StructureError::Parse {
            path: PathBuf::from(module.join("/")),
            source,
        })?;
        let mut c = ImportCollector {
            here: module.clone(),
            named: Vec::new(),
        };
        c.visit_file(&ast);
        let mut targets = BTreeSet::new();
        for path in c.named {
            // The longest prefix of the path that is a module file.
            let target = (0..=path.len())
                .rev()
                .map(|n| path[..n].to_vec())
                .find(|p| files.contains_key(p));
            if let Some(t) = target {
                let related = t.starts_with(module) || module.starts_with(&t);
                if !related {
                    targets.insert(t);
                }
            }
        }
        graph.insert(module.clone(), targets);
    }
    Ok(graph)
}

/// The strongly connected components of more than one module (Tarjan), each sorted.
pub fn cycles(graph: &BTreeMap<ModPath, BTreeSet<ModPath>>) -> Vec<Vec<ModPath>> {
    struct Tarjan<'g> {
        graph: &'g BTreeMap<ModPath, BTreeSet<ModPath>>,
        index: BTreeMap<&'g ModPath, usize>,
        low: BTreeMap<&'g ModPath, usize>,
        stack: Vec<&'g ModPath>,
        on_stack: BTreeSet<&'g ModPath>,
        out: Vec<Vec<ModPath>>,
    }
    impl<'g> Tarjan<'g> {
        fn visit(&mut self, v: &'g ModPath) {
            let i = self.index.len();
            self.index.insert(v, i);
            self.low.insert(v, i);
            self.stack.push(v);
            self.on_stack.insert(v);
            for w in self.graph.get(v).into_iter().flatten() {
                if !self.graph.contains_key(w) {
                    continue;
                }
                if !self.index.contains_key(w) {
                    self.visit(w);
                    let lw = self.low[w];
                    let lv = self.low[v];
                    self.low.insert(v, lv.min(lw));
                } else if self.on_stack.contains(w) {
                    let iw = self.index[w];
                    let lv = self.low[v];
                    self.low.insert(v, lv.min(iw));
                }
            }
            if self.low[v] == self.index[v] {
                let mut comp = Vec::new();
                while let Some(w) = self.stack.pop() {
                    self.on_stack.remove(w);
                    comp.push(w.clone());
                    if w == v {
                        break;
                    }
                }
                if comp.len() > 1 {
                    comp.sort();
                    self.out.push(comp);
                }
            }
        }
    }
    let mut t = Tarjan {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in graph.keys() {
        if !t.index.contains_key(v) {
            t.visit(v);
        }
    }
    t.out.sort();
    t.out
}

/// The import cycles of every checked crate's library (`src/` without `src/bin/`), as
/// `(crate, cycle)`.
pub fn workspace_cycles(root: &Path) -> Result<Vec<(String, Vec<ModPath>)>, StructureError> {
    let mut out = Vec::new();
    for krate in CRATES {
        let src = root.join(krate).join("src");
        let mut files = BTreeMap::new();
        for path in rust_files(&src)? {
            let rel = path.strip_prefix(&src).unwrap_or(&path);
            if rel.starts_with("bin") {
                continue;
            }
            files.insert(module_of(rel), read_source(&path)?);
        }
        for c in cycles(&import_graph(&files)?) {
            out.push((krate.to_string(), c));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lengths(src: &str) -> Vec<(String, usize)> {
        function_lengths(Path::new("x.rs"), src)
            .unwrap()
            .into_iter()
            .map(|f| (f.name, f.lines))
            .collect()
    }

    #[test]
    fn a_function_counts_from_fn_to_its_closing_brace() {
        let src = "/// doc\n#[inline]\npub fn three() {\n    let _ = 1;\n}\nfn one() {}\n";
        assert_eq!(
            lengths(src),
            vec![("three".to_string(), 3), ("one".to_string(), 1)]
        );
    }

    #[test]
    fn methods_are_named_by_their_type_and_nested_functions_count_alone_too() {
        let src = "struct S;\nimpl S {\n    fn m(&self) {\n        fn inner() {\n        }\n    }\n}\ntrait T {\n    fn d() {\n    }\n    fn no_body();\n}\n";
        assert_eq!(
            lengths(src),
            vec![
                ("S::m".to_string(), 4),
                ("inner".to_string(), 2),
                ("T::d".to_string(), 2),
            ]
        );
    }

    #[test]
    fn tests_are_skipped_but_not_cfg_not_test() {
        let src = "#[cfg(test)]\nmod tests {\n    fn helper() {}\n    #[test]\n    fn t() {}\n}\n#[test]\nfn top_test() {}\n#[cfg(not(test))]\nfn kept() {}\n";
        assert_eq!(lengths(src), vec![("kept".to_string(), 1)]);
    }

    fn m(s: &str) -> ModPath {
        s.split("::")
            .filter(|p| !p.is_empty())
            .map(String::from)
            .collect()
    }

    #[test]
    fn module_paths_of_files() {
        assert_eq!(module_of(Path::new("lib.rs")), m(""));
        assert_eq!(module_of(Path::new("tables/mod.rs")), m("tables"));
        assert_eq!(module_of(Path::new("tables/image.rs")), m("tables::image"));
    }

    #[test]
    fn a_sibling_cycle_is_found_and_parent_child_links_are_not_cycles() {
        let files: BTreeMap<ModPath, String> = [
            ("", "pub mod a; pub mod b; pub mod c; pub use a::X;"),
            ("a", "use crate::b::Y; pub struct X; fn f() { crate::X; }"),
            ("b", "pub struct Y; fn g() { super::c::h(); }"),
            (
                "c",
                "use super::a::X as Z; pub fn h() {} #[cfg(test)] mod tests { use crate::b::Y; }",
            ),
        ]
        .into_iter()
        .map(|(k, v)| (m(k), v.to_string()))
        .collect();
        let g = import_graph(&files).unwrap();
        assert_eq!(g[&m("a")], [m("b")].into_iter().collect());
        assert_eq!(g[&m("c")], [m("a")].into_iter().collect());
        assert_eq!(cycles(&g), vec![vec![m("a"), m("b"), m("c")]]);

        let mut acyclic = files.clone();
        acyclic.insert(m("b"), "pub struct Y;".to_string());
        assert!(cycles(&import_graph(&acyclic).unwrap()).is_empty());
    }
}
