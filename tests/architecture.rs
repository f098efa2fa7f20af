//! The shape of the code, checked from a real parser (`syn`):
//! - no file of a crate imports another file that imports it back, directly or through
//!   others (issue 36's rule, at file level since issue 45: `store/mod.rs` and
//!   `store/remote.rs` are two modules). A file's imports are every `crate::`, `super::`,
//!   `self::` or child-module path it names — in `use` trees (grouped, renamed or glob),
//!   expressions, types and macro arguments — outside items marked `#[cfg(test)]`; a path
//!   through a re-export (`pub use`) counts as an import of the module that defines the
//!   item, and so does a name a glob (`use m::*`, `pub use m::*`) brings in, found where it
//!   is defined; a macro a file invokes (`#[macro_use]` or by path) imports the file that
//!   defines it and whatever its body names (`$crate::…`, expanded in the caller). Doc
//!   comments are not code. The crate root (lib.rs, main.rs) may import every module, so it
//!   is no node of the graph; a crate with both has two trees, each checked, each holding
//!   the files its root's `mod` items reach.
//! - every crate depends only on crates of a lower layer of [`LAYERS`], the order
//!   docs/architecture.md draws.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use syn::visit::Visit;

/// The crates from the bottom layer up: a crate's `[dependencies]` may name only crates of
/// layers below its own (dev-dependencies are free: tests may use anything).
const LAYERS: &[&[&str]] = &[
    &["nrw-npy", "nrw-gemm"],
    &[
        "nrw-colmap",
        "nrw-knn",
        "nrw-style",
        "nrw-segment",
        "nrw-stereo",
    ],
    &["nrw-dataset", "nrw-render"],
    &["nrw-synth", "nrw-export"],
    &["nrw-qa", "nrw-trainer", "nrw-py"],
    &["nrw-pipeline"],
    &["nrw-etl"],
];

/// A module of a crate as the path from its root (`[]` is the root itself).
type ModPath = Vec<String>;

/// What one file says: the paths it names (from the module it is in, or an inline module of
/// it), and the names it re-exports.
#[derive(Default)]
struct FileFacts {
    /// (the inline module the path stands in, the path's segments).
    paths: Vec<(ModPath, Vec<String>)>,
    /// name → the path (from `module`) it re-exports.
    reexports: BTreeMap<String, (ModPath, Vec<String>)>,
    /// Glob imports: (the module they stand in, the path before `*`, whether `pub`).
    globs: Vec<(ModPath, Vec<String>, bool)>,
    /// Names the file defines at its top level (items, inline modules, macros).
    items: BTreeSet<String>,
    /// Names it uses alone (a one-segment path or a macro call), which a glob may bring in.
    bare: BTreeSet<String>,
    /// Macros it defines (`macro_rules!`): name → the paths their bodies name.
    macros: BTreeMap<String, Vec<Vec<String>>>,
    /// Macros it invokes by a bare name.
    calls: BTreeSet<String>,
    /// Child modules it declares from files (`mod x;`), as paths from the crate root.
    mods: Vec<ModPath>,
}

/// Whether the attributes hold `#[cfg(test)]` (alone: `cfg(all(test, …))` is rare here).
fn is_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg") && a.parse_args::<syn::Ident>().is_ok_and(|i| i == "test")
    })
}

/// Collects the paths of one file, skipping test items and descending into inline modules.
struct Collector {
    module: ModPath,
    /// The length of the file's own module path (inline modules are longer).
    base: usize,
    facts: FileFacts,
}

/// The name an item defines, for the items a glob can bring in.
fn item_name(i: &syn::Item) -> Option<&syn::Ident> {
    match i {
        syn::Item::Fn(x) => Some(&x.sig.ident),
        syn::Item::Struct(x) => Some(&x.ident),
        syn::Item::Enum(x) => Some(&x.ident),
        syn::Item::Const(x) => Some(&x.ident),
        syn::Item::Static(x) => Some(&x.ident),
        syn::Item::Trait(x) => Some(&x.ident),
        syn::Item::Type(x) => Some(&x.ident),
        syn::Item::Union(x) => Some(&x.ident),
        _ => None,
    }
}

impl Collector {
    /// Record a top-level name of the file (inline modules' items are theirs, not the file's).
    fn define(&mut self, name: &syn::Ident) {
        if self.module.len() == self.base {
            self.facts.items.insert(name.to_string());
        }
    }

    /// Every path of a `use` tree, with its last name (or `*`) and whether it is a glob.
    fn use_paths(
        tree: &syn::UseTree,
        prefix: &mut Vec<String>,
        out: &mut Vec<(Vec<String>, String)>,
    ) {
        match tree {
            syn::UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                Self::use_paths(&p.tree, prefix, out);
                prefix.pop();
            }
            syn::UseTree::Name(n) => {
                let mut v = prefix.clone();
                let name = n.ident.to_string();
                if name != "self" {
                    v.push(name.clone());
                }
                let name = if name == "self" {
                    prefix.last().cloned().unwrap_or_default()
                } else {
                    name
                };
                out.push((v, name));
            }
            syn::UseTree::Rename(r) => {
                let mut v = prefix.clone();
                if r.ident != "self" {
                    v.push(r.ident.to_string());
                }
                out.push((v, r.rename.to_string()));
            }
            syn::UseTree::Glob(_) => out.push((prefix.clone(), "*".into())),
            syn::UseTree::Group(g) => {
                for t in &g.items {
                    Self::use_paths(t, prefix, out);
                }
            }
        }
    }

    /// Paths inside a macro's tokens: every `crate`/`super`/`self` or plain name followed by
    /// `::` and more names.
    fn macro_paths(&mut self, tokens: proc_macro2::TokenStream) {
        let mut run: Vec<String> = Vec::new();
        let mut colons = 0;
        let flush = |run: &mut Vec<String>, facts: &mut FileFacts, module: &ModPath| {
            if run.len() > 1 {
                facts.paths.push((module.clone(), std::mem::take(run)));
            }
            run.clear();
        };
        for t in tokens {
            match t {
                proc_macro2::TokenTree::Ident(i) if run.is_empty() || colons == 2 => {
                    run.push(i.to_string());
                    colons = 0;
                }
                proc_macro2::TokenTree::Punct(p) if p.as_char() == ':' && !run.is_empty() => {
                    colons += 1;
                    if colons > 2 {
                        flush(&mut run, &mut self.facts, &self.module);
                        colons = 0;
                    }
                }
                proc_macro2::TokenTree::Group(g) => {
                    flush(&mut run, &mut self.facts, &self.module);
                    colons = 0;
                    self.macro_paths(g.stream());
                }
                other => {
                    flush(&mut run, &mut self.facts, &self.module);
                    colons = 0;
                    if let proc_macro2::TokenTree::Ident(i) = other {
                        run.push(i.to_string());
                    }
                }
            }
        }
        flush(&mut run, &mut self.facts, &self.module);
    }
}

impl<'ast> Visit<'ast> for Collector {
    fn visit_item(&mut self, i: &'ast syn::Item) {
        let attrs: &[syn::Attribute] = match i {
            syn::Item::Use(u) => &u.attrs,
            syn::Item::Mod(m) => &m.attrs,
            syn::Item::Fn(f) => &f.attrs,
            syn::Item::Impl(x) => &x.attrs,
            syn::Item::Struct(x) => &x.attrs,
            syn::Item::Enum(x) => &x.attrs,
            syn::Item::Const(x) => &x.attrs,
            syn::Item::Static(x) => &x.attrs,
            syn::Item::Trait(x) => &x.attrs,
            syn::Item::Type(x) => &x.attrs,
            syn::Item::Macro(x) => &x.attrs,
            _ => &[],
        };
        if is_test(attrs) {
            return;
        }
        match i {
            syn::Item::Use(u) => {
                let mut found = Vec::new();
                Self::use_paths(&u.tree, &mut Vec::new(), &mut found);
                let public = !matches!(u.vis, syn::Visibility::Inherited);
                for (path, name) in found {
                    if name == "*" {
                        self.facts
                            .globs
                            .push((self.module.clone(), path.clone(), public));
                    }
                    if public && name != "*" {
                        self.facts
                            .reexports
                            .insert(name, (self.module.clone(), path.clone()));
                    }
                    self.facts.paths.push((self.module.clone(), path));
                }
            }
            syn::Item::Mod(m) if m.content.is_some() => {
                self.define(&m.ident);
                self.module.push(m.ident.to_string());
                syn::visit::visit_item_mod(self, m);
                self.module.pop();
            }
            syn::Item::Mod(m) => {
                let mut child = self.module.clone();
                child.push(m.ident.to_string());
                self.facts.mods.push(child);
            }
            syn::Item::Macro(m) if m.mac.path.is_ident("macro_rules") => {
                // A definition imports nothing; its body's paths count where it expands.
                let Some(name) = &m.ident else { return };
                self.define(name);
                let mut body = Collector {
                    module: self.module.clone(),
                    base: self.base,
                    facts: FileFacts::default(),
                };
                body.macro_paths(m.mac.tokens.clone());
                let paths = body.facts.paths.into_iter().map(|(_, p)| p).collect();
                self.facts.macros.insert(name.to_string(), paths);
            }
            other => {
                if let Some(name) = item_name(other) {
                    self.define(name);
                }
                syn::visit::visit_item(self, other)
            }
        }
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        let segs: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
        if segs.len() > 1 {
            self.facts.paths.push((self.module.clone(), segs));
        } else if let Some(name) = segs.into_iter().next() {
            self.facts.bare.insert(name);
        }
        syn::visit::visit_path(self, p);
    }

    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        if let Some(name) = m.path.get_ident() {
            self.facts.calls.insert(name.to_string());
            self.facts.bare.insert(name.to_string());
        }
        self.macro_paths(m.tokens.clone());
        syn::visit::visit_macro(self, m);
    }
}

/// The facts of one file's text; `module` is the module the file is.
fn facts_of(text: &str, module: &ModPath, file: &Path) -> FileFacts {
    let ast = syn::parse_file(text).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let mut c = Collector {
        module: module.clone(),
        base: module.len(),
        facts: FileFacts::default(),
    };
    c.visit_file(&ast);
    c.facts
}

/// The module a file under `src` is: `a.rs` and `a/mod.rs` are `a`, `a/b.rs` is `a::b`,
/// lib.rs and main.rs the root.
fn module_of(src: &Path, file: &Path) -> ModPath {
    let rel = file.strip_prefix(src).unwrap();
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    let root = parts.is_empty() && (stem == "lib" || stem == "main");
    if !(root || stem == "mod") {
        parts.push(stem.to_string());
    }
    parts
}

/// A crate's files as modules, and what each says.
struct CrateFacts {
    files: BTreeMap<ModPath, FileFacts>,
}

impl CrateFacts {
    /// The tree of the crate root `root` (lib.rs or main.rs): the root and every file its
    /// `mod` items reach, directly or through other files.
    fn read(src: &Path, root: &str) -> CrateFacts {
        let mut files = BTreeMap::new();
        let mut todo = vec![src.join(root)];
        while let Some(f) = todo.pop() {
            let m = module_of(src, &f);
            let text = std::fs::read_to_string(&f).unwrap();
            let facts = facts_of(&text, &m, &f);
            for child in &facts.mods {
                let stem = src.join(child.join("/"));
                let file = stem.with_extension("rs");
                let folder = stem.join("mod.rs");
                todo.extend([file, folder].into_iter().filter(|p| p.is_file()));
            }
            files.insert(m, facts);
        }
        CrateFacts { files }
    }

    /// Every tree of the crate under `src`: lib.rs's, main.rs's, or both.
    fn roots(src: &Path) -> Vec<(&'static str, CrateFacts)> {
        ["lib.rs", "main.rs"]
            .into_iter()
            .filter(|r| src.join(r).is_file())
            .map(|r| (r, CrateFacts::read(src, r)))
            .collect()
    }

    /// The file module that defines `name` as seen from `module`: its own item, a name it
    /// re-exports, or one a `pub use …::*` of it brings in.
    fn find_item(&self, module: &ModPath, name: &str, depth: usize) -> Option<ModPath> {
        let f = self.files.get(module)?;
        if f.items.contains(name) || f.macros.contains_key(name) {
            return Some(module.clone());
        }
        if depth >= 8 {
            return None;
        }
        if let Some((m, p)) = f.reexports.get(name) {
            return self.resolve(m, p, depth + 1);
        }
        f.globs
            .iter()
            .filter(|(_, _, public)| *public)
            .filter_map(|(m, p, _)| self.resolve(m, p, depth + 1))
            .find_map(|t| self.find_item(&t, name, depth + 1))
    }

    /// The file module a path named in `from` (a module, maybe inline) lands in, following
    /// re-exports; None for other crates' paths and the crate's own root items.
    fn resolve(&self, from: &ModPath, path: &[String], depth: usize) -> Option<ModPath> {
        let (first, rest) = path.split_first()?;
        let mut base: ModPath = match first.as_str() {
            "crate" => Vec::new(),
            "self" => from.clone(),
            "super" => {
                let mut b = from.clone();
                b.pop()?;
                b
            }
            _ => {
                // A name relative to the module is a child module of it, or another crate's.
                let mut child = from.clone();
                child.push(first.clone());
                if !self.files.contains_key(&child) {
                    return None;
                }
                return self.walk(child, rest, depth);
            }
        };
        let mut rest = rest;
        while rest.first().is_some_and(|s| s == "super") {
            base.pop()?;
            rest = &rest[1..];
        }
        self.walk(base, rest, depth)
    }

    /// From module `base`, down `rest` as far as files go, then through a re-export.
    fn walk(&self, mut base: ModPath, rest: &[String], depth: usize) -> Option<ModPath> {
        let mut i = 0;
        while i < rest.len() {
            let mut next = base.clone();
            next.push(rest[i].clone());
            if !self.files.contains_key(&next) {
                break;
            }
            base = next;
            i += 1;
        }
        if let (Some(name), true) = (rest.get(i), depth < 8) {
            if let Some((m, p)) = self.files.get(&base).and_then(|f| f.reexports.get(name)) {
                let mut target = p.clone();
                target.extend(rest[i + 1..].iter().cloned());
                if let Some(t) = self.resolve(m, &target, depth + 1) {
                    return Some(t);
                }
            }
            // A name a `pub use …::*` brings in: where it is defined.
            if let Some(t) = self.find_item(&base, name, depth + 1) {
                return Some(t);
            }
        }
        Some(base)
    }

    /// File module → the file modules of the crate it imports (the root left out).
    fn graph(&self) -> BTreeMap<String, BTreeSet<String>> {
        let name = |m: &ModPath| m.join("::");
        let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (file, facts) in &self.files {
            if file.is_empty() {
                continue;
            }
            let mut targets: Vec<ModPath> = facts
                .paths
                .iter()
                .filter_map(|(from, path)| self.resolve(from, path, 0))
                .collect();
            targets.extend(self.glob_targets(facts));
            targets.extend(self.macro_targets(facts));
            let deps = g.entry(name(file)).or_default();
            for t in targets {
                if !t.is_empty() && &t != file {
                    deps.insert(name(&t));
                }
            }
        }
        g
    }

    /// Where the bare names a file uses are defined, for each glob it imports through.
    fn glob_targets(&self, facts: &FileFacts) -> Vec<ModPath> {
        let mut out = Vec::new();
        for (from, path, _) in &facts.globs {
            let Some(t) = self.resolve(from, path, 0) else {
                continue;
            };
            out.extend(facts.bare.iter().filter_map(|n| self.find_item(&t, n, 0)));
        }
        out
    }

    /// For each macro a file invokes by name: the file that defines it, and what its body
    /// names (resolved from there, as `$crate::…` is).
    fn macro_targets(&self, facts: &FileFacts) -> Vec<ModPath> {
        let mut out = Vec::new();
        for (module, f) in &self.files {
            for (name, body) in &f.macros {
                if !facts.calls.contains(name) {
                    continue;
                }
                out.push(module.clone());
                out.extend(body.iter().filter_map(|p| self.resolve(module, p, 0)));
            }
        }
        out
    }
}

/// A cycle of `g`, if it has one (depth-first search).
fn cycle(g: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        m: &str,
        g: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == m) {
            let mut c = path[i..].to_vec();
            c.push(m.to_string());
            return Some(c);
        }
        if done.contains(m) || !g.contains_key(m) {
            return None;
        }
        path.push(m.to_string());
        for d in &g[m] {
            if let Some(c) = visit(d, g, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m.to_string());
        None
    }
    let mut done = BTreeSet::new();
    g.keys()
        .find_map(|m| visit(m, g, &mut Vec::new(), &mut done))
}

/// The workspace's crate folders (crates/* and python/), with their package names.
fn workspace_crates() -> Vec<(String, PathBuf)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root.join("crates"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    dirs.push(root.join("python"));
    dirs.sort();
    dirs.into_iter()
        .filter_map(|d| {
            let text = std::fs::read_to_string(d.join("Cargo.toml")).ok()?;
            let t: toml::Table = toml::from_str(&text).unwrap();
            let name = t["package"]["name"].as_str()?.to_string();
            Some((name, d))
        })
        .collect()
}

/// The circle of the crate whose sources are under `src`, if any (in either of its trees).
fn circle_in(src: &Path) -> Option<Vec<String>> {
    CrateFacts::roots(src)
        .into_iter()
        .find_map(|(_, c)| cycle(&c.graph()))
}

/// Whether a crate's `src` is its root file alone (nothing to draw a graph of).
fn one_file(src: &Path) -> bool {
    std::fs::read_dir(src).is_ok_and(|d| d.count() == 1)
}

#[test]
fn no_file_of_a_crate_imports_one_that_imports_it_back() {
    let (mut checked, mut circles) = (Vec::new(), Vec::new());
    for (name, dir) in workspace_crates() {
        let src = dir.join("src");
        for (root, facts) in CrateFacts::roots(&src) {
            let g = facts.graph();
            assert!(
                g.len() > 1 || name == "nrw-knn" || root == "main.rs" || one_file(&src),
                "{}/{root}: no modules found",
                src.display()
            );
            if let Some(c) = cycle(&g) {
                circles.push(format!(
                    "{}/{root}: import circle {}",
                    src.display(),
                    c.join(" → ")
                ));
            }
        }
        checked.push(name);
    }
    assert!(circles.is_empty(), "{}", circles.join("\n"));
    // Edges the first version of this check missed, so the graph is known to see them: a
    // grouped capitalised import through the root's re-exports, imports after a
    // `#[cfg(test)]` item, and a file inside a folder module.
    let crates: BTreeMap<String, PathBuf> = workspace_crates().into_iter().collect();
    let graph = |c: &str| CrateFacts::read(&crates[c].join("src"), "lib.rs").graph();
    let edge = |g: &BTreeMap<String, BTreeSet<String>>, a: &str, b: &str| {
        assert!(g[a].contains(b), "{a} → {b} not seen: {:?}", g[a]);
    };
    let pipeline = graph("nrw-pipeline");
    edge(&pipeline, "stage", "progress");
    edge(&pipeline, "stage", "units");
    edge(&pipeline, "ingest::view", "ingest::config");
    let style = graph("nrw-style");
    // winograd.rs's imports after its `#[cfg(test)] use crate::isa::…`, and the `isa` its
    // `multiversion!` invocations (a `#[macro_use]` macro of isa.rs) expand to.
    edge(&style, "winograd", "matmul");
    edge(&style, "winograd", "tensor");
    edge(&style, "winograd", "isa");
    edge(&graph("nrw-npy"), "read::pickle", "read::array");
    edge(&graph("nrw-dataset"), "store::chunks", "store::remote");
    assert!(
        checked.len() >= 13 && checked.iter().any(|c| c == "nrw-py"),
        "{checked:?}"
    );
}

/// The layer of `krate` in [`LAYERS`].
fn layer(krate: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&krate))
}

/// The crate's workspace dependencies that are not below it, as (dependency, its layer).
fn upward_dependencies(krate: &str, manifest: &str) -> Vec<String> {
    let t: toml::Table = toml::from_str(manifest).unwrap();
    let own = layer(krate).unwrap_or_else(|| panic!("{krate} is in no layer of LAYERS"));
    let deps = t.get("dependencies").and_then(|d| d.as_table());
    deps.into_iter()
        .flat_map(|d| d.keys())
        .filter(|d| d.starts_with("nrw-"))
        .filter(|d| layer(d).is_none_or(|l| l >= own))
        .cloned()
        .collect()
}

#[test]
fn every_crate_depends_only_on_crates_of_lower_layers() {
    let crates = workspace_crates();
    let names: BTreeSet<&str> = crates.iter().map(|(n, _)| n.as_str()).collect();
    let listed: BTreeSet<&str> = LAYERS.iter().flat_map(|l| l.iter().copied()).collect();
    assert_eq!(
        names, listed,
        "LAYERS lists every crate of the workspace once"
    );
    for (name, dir) in &crates {
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
        let up = upward_dependencies(name, &manifest);
        assert!(
            up.is_empty(),
            "{name} depends on {up:?}, not below it in LAYERS"
        );
    }
}

/// A scratch crate of `files` (path under src → text).
fn planted(files: &[(&str, &str)]) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    for (p, text) in files {
        let f = tmp.path().join(p);
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
        std::fs::write(f, text).unwrap();
    }
    tmp
}

#[test]
fn planted_circles_fail_the_check_in_every_form() {
    let root = (
        "lib.rs",
        "mod a;\nmod b;\nmod store;\npub use a::Progress;\n",
    );
    let cases: &[(&str, &[(&str, &str)])] = &[
        (
            "grouped capitalised names through the root's re-export",
            &[
                ("a.rs", "use crate::b::helper;\npub struct Progress;\n"),
                ("b.rs", "use crate::{Progress, Unit};\npub fn helper() {}\n"),
            ],
        ),
        (
            "the other direction, through an expression path",
            &[
                (
                    "a.rs",
                    "pub struct Progress;\npub fn f() { crate::b::helper() }\n",
                ),
                ("b.rs", "pub fn helper() { let _ = crate::a::Progress; }\n"),
            ],
        ),
        (
            "inside a folder module (mod.rs ↔ its file)",
            &[
                ("a.rs", "pub struct Progress;\n"),
                ("b.rs", ""),
                (
                    "store/mod.rs",
                    "mod remote;\npub struct Store;\npub fn open() { remote::connect() }\n",
                ),
                (
                    "store/remote.rs",
                    "use super::Store;\npub fn connect() {}\n",
                ),
            ],
        ),
        (
            "behind an earlier #[cfg(test)] item",
            &[
                (
                    "a.rs",
                    "#[cfg(test)]\nuse std::fmt;\npub struct Progress;\nuse crate::b::helper;\n",
                ),
                (
                    "b.rs",
                    "pub fn helper() -> crate::a::Progress { todo!() }\n",
                ),
            ],
        ),
        (
            "through a macro's arguments",
            &[
                ("a.rs", "pub struct Progress;\nuse crate::b::helper;\n"),
                (
                    "b.rs",
                    "pub fn helper() { println!(\"{:?}\", crate::a::Progress); }\n",
                ),
            ],
        ),
    ];
    for (what, files) in cases {
        let mut all = vec![root];
        all.extend_from_slice(files);
        let tmp = planted(&all);
        assert!(circle_in(tmp.path()).is_some(), "{what}: circle not found");
    }
    // No circle: a doc link, a test module's import and another crate's path are no imports.
    let tmp = planted(&[
        root,
        ("a.rs", "use crate::b::helper;\npub struct Progress;\n"),
        (
            "b.rs",
            "/// Like [`crate::a::Progress`].\npub fn helper() { nrw_other::a::x(); }\n#[cfg(test)]\nmod tests { use crate::a::Progress; }\n",
        ),
        ("store/mod.rs", "mod remote;\npub fn open() { remote::connect() }\n"),
        ("store/remote.rs", "pub fn connect() {}\n"),
    ]);
    assert_eq!(circle_in(tmp.path()), None);
}

#[test]
fn planted_circles_through_globs_macros_and_a_library_beside_a_binary_fail_the_check() {
    let cases: &[(&str, &[(&str, &str)])] = &[
        (
            "a name the root re-exports by glob (`pub use a::*`)",
            &[
                ("lib.rs", "mod a;\nmod b;\npub use a::*;\n"),
                ("a.rs", "use crate::b::helper;\npub struct Progress;\n"),
                ("b.rs", "use crate::Progress;\npub fn helper() {}\n"),
            ],
        ),
        (
            "a bare name a glob import of the root brings in (`use crate::*`)",
            &[
                ("lib.rs", "mod a;\nmod b;\npub use a::Progress;\n"),
                ("a.rs", "use crate::b::helper;\npub struct Progress;\n"),
                (
                    "b.rs",
                    "use crate::*;\npub fn helper() -> Progress { todo!() }\n",
                ),
            ],
        ),
        (
            "a #[macro_use] macro's body, expanded in its caller",
            &[
                ("lib.rs", "#[macro_use]\nmod m;\nmod a;\nmod b;\n"),
                (
                    "m.rs",
                    "macro_rules! call_b { () => { $crate::b::helper() }; }\n",
                ),
                ("a.rs", "pub struct Progress;\npub fn f() { call_b!() }\n"),
                ("b.rs", "pub fn helper() { let _ = crate::a::Progress; }\n"),
            ],
        ),
        (
            "the file defining a macro its caller's file is imported by",
            &[
                ("lib.rs", "#[macro_use]\nmod m;\nmod a;\n"),
                (
                    "m.rs",
                    "macro_rules! noop { () => {}; }\npub fn g() { crate::a::f() }\n",
                ),
                ("a.rs", "pub fn f() { noop!() }\n"),
            ],
        ),
        (
            "lib.rs's re-export in a crate that also has main.rs",
            &[
                ("lib.rs", "mod a;\nmod b;\npub use a::Progress;\n"),
                ("main.rs", "fn main() {}\n"),
                ("a.rs", "use crate::b::helper;\npub struct Progress;\n"),
                ("b.rs", "use crate::Progress;\npub fn helper() {}\n"),
            ],
        ),
    ];
    for (what, files) in cases {
        let tmp = planted(files);
        assert!(circle_in(tmp.path()).is_some(), "{what}: circle not found");
    }
    // No circle: a glob whose module does not define the name, a macro defined and not
    // called, and a binary's own module importing the library tree's file of the same name.
    let tmp = planted(&[
        (
            "lib.rs",
            "#[macro_use]\nmod m;\nmod a;\nmod b;\npub use b::*;\n",
        ),
        (
            "m.rs",
            "macro_rules! call_a { () => { $crate::a::f() }; }\n",
        ),
        ("a.rs", "use crate::b::helper;\npub fn f() {}\n"),
        (
            "b.rs",
            "use crate::*;\npub fn helper() { let _ = Progress; }\n",
        ),
        ("main.rs", "mod cli;\nfn main() {}\n"),
        ("cli.rs", "pub fn run() {}\n"),
    ]);
    assert_eq!(circle_in(tmp.path()), None);
}

#[test]
fn a_crate_importing_one_above_it_fails_the_layer_check() {
    let up = upward_dependencies(
        "nrw-dataset",
        "[package]\nname = \"nrw-dataset\"\n[dependencies]\nnrw-colmap.workspace = true\nnrw-pipeline = { path = \"../nrw-pipeline\" }\nnrw-render.workspace = true\n[dev-dependencies]\nnrw-etl.workspace = true\n",
    );
    assert_eq!(up, ["nrw-pipeline", "nrw-render"]);
    let g: BTreeMap<String, BTreeSet<String>> = [("a", vec!["b"]), ("b", vec!["a"])]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.into_iter().map(String::from).collect()))
        .collect();
    assert_eq!(cycle(&g).unwrap(), vec!["a", "b", "a"]);
}

/// Lines a function of `src/` may run to (issue 61: small functions with one job).
const FUNCTION_LINES: usize = 80;

/// The functions of `src/` that ran past [`FUNCTION_LINES`] when this check came (crate, file
/// from `src/`, name, lines): each may shrink, none may grow, and no other may join them.
const LONG_FUNCTIONS: &[(&str, &str, &str, usize)] = &[];

/// Functions (free, in impls and with bodies in traits) outside test code, with their lines
/// from `fn` to the closing brace.
struct FunctionLengths {
    found: Vec<(String, usize)>,
}

impl<'ast> Visit<'ast> for FunctionLengths {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if !is_test(&m.attrs) {
            syn::visit::visit_item_mod(self, m);
        }
    }
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if !is_test(&f.attrs) && !f.attrs.iter().any(|a| a.path().is_ident("test")) {
            self.add(&f.sig, &f.block);
            syn::visit::visit_item_fn(self, f);
        }
    }
    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        if !is_test(&f.attrs) {
            self.add(&f.sig, &f.block);
            syn::visit::visit_impl_item_fn(self, f);
        }
    }
    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        if let Some(block) = &f.default {
            self.add(&f.sig, block);
        }
        syn::visit::visit_trait_item_fn(self, f);
    }
}

impl FunctionLengths {
    fn add(&mut self, sig: &syn::Signature, block: &syn::Block) {
        let lines = block.brace_token.span.close().end().line + 1 - sig.fn_token.span.start().line;
        self.found.push((sig.ident.to_string(), lines));
    }
}

/// Every function of the workspace's `src/` folders longer than [`FUNCTION_LINES`], as
/// (crate, file from `src/`, name, lines); files that are test modules (`tests.rs`) skipped.
fn long_functions() -> Vec<(String, String, String, usize)> {
    let mut out = Vec::new();
    for (name, dir) in workspace_crates() {
        let src = dir.join("src");
        for file in rs_files(&src) {
            let rel = file
                .strip_prefix(&src)
                .unwrap()
                .to_string_lossy()
                .into_owned();
            if rel.ends_with("tests.rs") || rel.contains("tests/") {
                continue;
            }
            let text = std::fs::read_to_string(&file).unwrap();
            let ast = syn::parse_file(&text).unwrap_or_else(|e| panic!("{rel}: {e}"));
            let mut v = FunctionLengths { found: Vec::new() };
            v.visit_file(&ast);
            out.extend(
                v.found
                    .into_iter()
                    .filter(|(_, n)| *n > FUNCTION_LINES)
                    .map(|(f, n)| (name.clone(), rel.clone(), f, n)),
            );
        }
    }
    out.sort();
    out
}

/// The `.rs` files under `dir`, recursively.
fn rs_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(rs_files(&p));
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
    out
}

#[test]
fn no_function_grows_past_80_lines() {
    let found = long_functions();
    let mut problems = Vec::new();
    for (krate, file, f, n) in &found {
        let known = LONG_FUNCTIONS
            .iter()
            .find(|(k, fl, name, _)| k == krate && fl == file && name == f);
        match known {
            None => problems.push(format!(
                "{krate} {file}: {f} runs {n} lines (at most {FUNCTION_LINES})"
            )),
            Some((.., ceiling)) if n > ceiling => problems.push(format!(
                "{krate} {file}: {f} grew to {n} lines (was {ceiling})"
            )),
            _ => {}
        }
    }
    let listing: String = found
        .iter()
        .map(|(k, fl, f, n)| format!("    (\"{k}\", \"{fl}\", \"{f}\", {n}),\n"))
        .collect();
    eprintln!(
        "{} functions over {FUNCTION_LINES} lines:\n{listing}",
        found.len()
    );
    assert!(
        problems.is_empty(),
        "{}\n(all of them now:\n{listing})",
        problems.join("\n")
    );
}

#[test]
fn a_planted_long_function_is_measured_from_fn_to_its_closing_brace() {
    let body: String = (0..90).map(|i| format!("    let _x{i} = {i};\n")).collect();
    let text = format!("fn short() {{}}\n\n/// Doc.\nfn long() {{\n{body}}}\n#[cfg(test)]\nmod tests {{ fn hidden() {{\n{body}}} }}\n");
    let mut v = FunctionLengths { found: Vec::new() };
    v.visit_file(&syn::parse_file(&text).unwrap());
    assert_eq!(
        v.found,
        vec![("short".to_string(), 1), ("long".to_string(), 92)]
    );
}
