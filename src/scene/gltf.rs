//! Loading a scene from glTF 2.0: `.gltf` (JSON) with its buffers in files beside it
//! (relative URIs, `%XX` escapes decoded) or embedded as base64 `data:` URIs, or `.glb`
//! (binary, buffers inside). The JSON is parsed and validated by the `gltf` crate; the
//! vertex and index data are read here, after checking that every accessor lies inside
//! its buffer view and every view inside its buffer (so a short or missing buffer is an
//! error naming it, never a wrong mesh).
//!
//! The nodes of the default scene (else the first) are walked from the roots with their
//! transforms (after a check that the hierarchy has no cycle and expands to at most
//! [`MAX_NODE_INSTANCES`] nodes; the walk keeps its own stack, so a deep legal chain
//! is no error); every triangle primitive of a node's mesh becomes faces (a transform
//! that mirrors reverses the corner order, so fronts stay fronts). Groups: the node's
//! name, else its mesh's, else `node<N>`. Materials: `baseColorFactor` (rgb) is the
//! reflectance Kd (clamped below 1 with a warning, since a white of exactly 1 keeps all
//! light), `emissiveFactor` × `KHR_materials_emissive_strength` the exitance Ke, in the
//! scene's radiosity units; a negative base colour, emissive factor or strength is an
//! error, as a negative Kd or Ke in MTL; textures are ignored. Only asset version 2.x
//! is read. A materials file beside the file
//! ([`super::mesh::materials_file`]) overrides by group name. Triangles are numbered
//! from 1 over the primitives in walk order: errors and warnings name them so.

use std::collections::HashMap;
use std::path::Path;

use glam::DMat4;

use super::mesh::{check_point, one_line, Assembler};
use super::{Material, Scene, SceneError};

const UNIT: &str = "triangle";

/// Most node instances a walk makes: a node whose parents share it is walked once per
/// path from a root, which a crafted file (each level's node the child of both nodes
/// of the level above) makes 2^depth; a million instances is far above any real scene
/// (glTF hierarchies are trees: the glTF 2.0 specification, "Nodes and Hierarchy":
/// "each node MUST have zero or one parent node").
const MAX_NODE_INSTANCES: u64 = 1_000_000;

/// Largest reflectance a base colour becomes.
const MAX_KD: f32 = 0.99;

/// Load a `.gltf` or `.glb` file.
///
/// # Errors
/// [`SceneError::Read`] when the file cannot be read; [`SceneError::Element`] naming the
/// buffer, accessor, primitive or triangle for a file the `gltf` crate refuses, a
/// missing or short buffer, an accessor outside its data, a primitive that is not
/// triangles, an index out of range or a coordinate that is not finite;
/// [`SceneError::Empty`] when no triangle is usable.
pub(super) fn load_gltf(path: &Path) -> Result<Scene, SceneError> {
    let bytes = crate::input::read(path).map_err(|cause| SceneError::Read {
        path: path.to_owned(),
        cause,
    })?;
    let err = |element: String, reason: String| SceneError::Element {
        path: path.to_owned(),
        element,
        reason,
    };
    let gltf = ::gltf::Gltf::from_slice(&bytes).map_err(|e| {
        err(
            "file".into(),
            format!("not readable as glTF 2.0: {}", one_line(e)),
        )
    })?;
    let doc = &gltf.document;
    let version = &doc.as_json().asset.version;
    if !version.starts_with("2.") {
        return Err(err(
            "asset".into(),
            format!("version `{version}`: only glTF 2.x is read"),
        ));
    }
    let buffers = load_buffers(path, &gltf)?;

    let mut load = Load {
        path,
        out: Assembler::new(path, UNIT)?,
        buffers,
        materials: HashMap::new(),
        next: 1,
    };
    let roots: Vec<::gltf::Node<'_>> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => Vec::new(),
    };
    let under = instances(doc).map_err(|(node, child)| {
        err(
            format!("node {node}"),
            format!(
                "has node {child} among its descendants and as a child: the hierarchy has a cycle"
            ),
        )
    })?;
    let total = roots
        .iter()
        .fold(0u64, |t, r| t.saturating_add(under[r.index()]));
    if total > MAX_NODE_INSTANCES {
        let shared = shared_node(doc).map_or(String::new(), |(c, a, b)| {
            format!(" (node {c} is a child of nodes {a} and {b}; glTF hierarchies are trees)")
        });
        return Err(err(
            "nodes".into(),
            format!(
                "the scene's hierarchy expands to {total} node instances, more than the {MAX_NODE_INSTANCES} read{shared}"
            ),
        ));
    }
    for node in &roots {
        load.node(node, DMat4::IDENTITY)?;
    }
    load.out.finish()
}

/// For each node, the instances a walk from it makes (itself and every descendant,
/// once per path; saturating), found in one pass (each node counted once, from its
/// children's counts), without recursion so that a deep legal chain costs no stack.
///
/// # Errors
/// `(node, child)` when following `child` from `node` closes a cycle (the child is on
/// the path being walked: an on-stack set, so a node reached twice by two paths is no
/// cycle).
fn instances(doc: &::gltf::Document) -> Result<Vec<u64>, (usize, usize)> {
    let children: Vec<Vec<usize>> = doc
        .nodes()
        .map(|n| n.children().map(|c| c.index()).collect())
        .collect();
    const NEW: u8 = 0;
    const ON_PATH: u8 = 1;
    const DONE: u8 = 2;
    let mut state = vec![NEW; children.len()];
    let mut count = vec![0u64; children.len()];
    for start in 0..children.len() {
        if state[start] != NEW {
            continue;
        }
        state[start] = ON_PATH;
        let mut path = vec![(start, 0usize)];
        while let Some((v, next)) = path.last_mut() {
            let v = *v;
            if let Some(&c) = children[v].get(*next) {
                *next += 1;
                match state[c] {
                    NEW => {
                        state[c] = ON_PATH;
                        path.push((c, 0));
                    }
                    ON_PATH => return Err((v, c)),
                    _ => {}
                }
            } else {
                count[v] = children[v]
                    .iter()
                    .fold(1u64, |t, &c| t.saturating_add(count[c]));
                state[v] = DONE;
                path.pop();
            }
        }
    }
    Ok(count)
}

/// A node with two parents, as (node, parent, other parent), for the message.
fn shared_node(doc: &::gltf::Document) -> Option<(usize, usize, usize)> {
    let mut parent: HashMap<usize, usize> = HashMap::new();
    for n in doc.nodes() {
        for c in n.children() {
            if let Some(&p) = parent.get(&c.index()) {
                return Some((c.index(), p, n.index()));
            }
            parent.insert(c.index(), n.index());
        }
    }
    None
}

/// The data of every buffer: the GLB's binary chunk, or a file the URI names relative
/// to the glTF file; each at least as long as its `byteLength`.
fn load_buffers(path: &Path, gltf: &::gltf::Gltf) -> Result<Vec<Vec<u8>>, SceneError> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut out = Vec::new();
    for b in gltf.document.buffers() {
        let name = format!("buffer {}", b.index());
        let err = |reason: String| SceneError::Element {
            path: path.to_owned(),
            element: name.clone(),
            reason,
        };
        let data = match b.source() {
            ::gltf::buffer::Source::Bin => gltf.blob.clone().ok_or_else(|| {
                err("refers to the GLB binary chunk, which the file does not have".into())
            })?,
            ::gltf::buffer::Source::Uri(uri) => match uri
                .get(..5)
                .filter(|scheme| scheme.eq_ignore_ascii_case("data:"))
            {
                Some(_) => data_uri(&uri[5..]).map_err(err)?,
                None => {
                    let file = dir.join(percent_decoded(uri));
                    crate::input::read(&file)
                        .map_err(|e| err(format!("cannot read {}: {e}", file.display())))?
                }
            },
        };
        if data.len() < b.length() {
            return Err(err(format!(
                "has {} bytes, its byteLength says {}: truncated",
                data.len(),
                b.length()
            )));
        }
        out.push(data);
    }
    Ok(out)
}

/// The bytes of a `data:` URI (RFC 2397) after its scheme: `[media type][;base64],data`.
/// Only base64 data is taken (what glTF exporters write), padded or not; the scheme and
/// the `;base64` token in any case. Err: why not.
fn data_uri(rest: &str) -> Result<Vec<u8>, String> {
    use base64::engine::{general_purpose, DecodePaddingMode, GeneralPurpose};
    use base64::Engine as _;
    let (head, data) = rest
        .split_once(',')
        .ok_or("data: URI without the comma before its data")?;
    let h = head.as_bytes();
    let base64 = h.len() >= 7 && h[h.len() - 7..].eq_ignore_ascii_case(b";base64");
    if !base64 {
        return Err(format!(
            "data: URI `data:{head},...` is not base64 (only base64 data: URIs are read)"
        ));
    }
    let engine = GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        general_purpose::PAD.with_decode_padding_mode(DecodePaddingMode::Indifferent),
    );
    engine
        .decode(data.trim_end())
        .map_err(|e| format!("data: URI is not valid base64: {e}"))
}

/// A relative URI as a path: `%XX` escapes decoded (glTF URIs are RFC 3986, so a file
/// `my mesh.bin` is written `my%20mesh.bin`). A `%` not followed by two hex digits is
/// kept as it is. The bytes are the name as they are (a Unix file name need not be
/// UTF-8); elsewhere a name that is not UTF-8 has its bad bytes replaced.
fn percent_decoded(uri: &str) -> std::path::PathBuf {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut k = 0;
    while k < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (
            b[k],
            b.get(k + 1).and_then(|&c| hex(c)),
            b.get(k + 2).and_then(|&c| hex(c)),
        ) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                k += 3;
            }
            (c, _, _) => {
                out.push(c);
                k += 1;
            }
        }
    }
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStringExt;
        std::ffi::OsString::from_vec(out).into()
    }
    #[cfg(not(unix))]
    {
        String::from_utf8_lossy(&out).into_owned().into()
    }
}

/// The state of one load: where faces go, the buffers, the glTF materials already
/// converted, and the number of the next triangle.
struct Load<'p> {
    path: &'p Path,
    out: Assembler<'p>,
    buffers: Vec<Vec<u8>>,
    materials: HashMap<usize, u32>,
    next: u32,
}

impl Load<'_> {
    fn err(&self, element: String, reason: String) -> SceneError {
        SceneError::Element {
            path: self.path.to_owned(),
            element,
            reason,
        }
    }

    /// Walk `root` and its descendants in pre-order (a node, then its children in
    /// order), each with its world transform, without recursion: [`instances`] has
    /// checked that the walk ends and how long it is.
    fn node(&mut self, root: &::gltf::Node<'_>, parent: DMat4) -> Result<(), SceneError> {
        let mut todo = vec![(root.clone(), parent)];
        while let Some((node, parent)) = todo.pop() {
            let m = node.transform().matrix().map(|c| c.map(f64::from));
            let world = parent * DMat4::from_cols_array_2d(&m);
            if let Some(mesh) = node.mesh() {
                let group = node
                    .name()
                    .or(mesh.name())
                    .map(str::to_owned)
                    .unwrap_or_else(|| format!("node{}", node.index()));
                for prim in mesh.primitives() {
                    self.primitive(&prim, &group, world, mesh.index())?;
                }
            }
            let children: Vec<_> = node.children().collect();
            todo.extend(children.into_iter().rev().map(|c| (c, world)));
        }
        Ok(())
    }

    fn primitive(
        &mut self,
        prim: &::gltf::Primitive<'_>,
        group: &str,
        world: DMat4,
        mesh: usize,
    ) -> Result<(), SceneError> {
        let here = format!("mesh {mesh} primitive {}", prim.index());
        if prim.mode() != ::gltf::mesh::Mode::Triangles {
            return Err(self.err(
                here,
                format!("mode {:?}: only triangle lists are read", prim.mode()),
            ));
        }
        let pos = prim
            .get(&::gltf::Semantic::Positions)
            .ok_or_else(|| self.err(here.clone(), "no POSITION attribute".into()))?;
        use ::gltf::accessor::{DataType, Dimensions};
        if pos.data_type() != DataType::F32 || pos.dimensions() != Dimensions::Vec3 {
            return Err(self.err(
                format!("accessor {}", pos.index()),
                "POSITION must be float VEC3".into(),
            ));
        }
        let raw = self.accessor(&pos, 12)?;
        let positions: Vec<[f64; 3]> = raw
            .map(|b| {
                let f =
                    |k: usize| f64::from(f32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]));
                [f(0), f(4), f(8)]
            })
            .collect();
        let indices: Vec<u64> = match prim.indices() {
            None => (0..positions.len() as u64).collect(),
            Some(acc) => {
                let size = match (acc.data_type(), acc.dimensions()) {
                    (DataType::U8, Dimensions::Scalar) => 1,
                    (DataType::U16, Dimensions::Scalar) => 2,
                    (DataType::U32, Dimensions::Scalar) => 4,
                    _ => {
                        return Err(self.err(
                            format!("accessor {}", acc.index()),
                            "indices must be unsigned byte, short or int scalars".into(),
                        ))
                    }
                };
                self.accessor(&acc, size)?
                    .map(|b| b.iter().rev().fold(0u64, |v, &x| (v << 8) | u64::from(x)))
                    .collect()
            }
        };
        if !indices.len().is_multiple_of(3) {
            return Err(self.err(
                here,
                format!("{} indices: not a whole number of triangles", indices.len()),
            ));
        }
        let material = self.material(prim, group)?;
        let mirror = world.determinant() < 0.0;
        for tri in indices.chunks_exact(3) {
            let at = self.next;
            self.next += 1;
            let mut corners = Vec::with_capacity(3);
            for &i in tri {
                let p = positions.get(i as usize).ok_or_else(|| {
                    self.err(
                        format!("{UNIT} {at} ({here})"),
                        format!(
                            "vertex index {i} out of range ({} vertices)",
                            positions.len()
                        ),
                    )
                })?;
                let p = check_point(self.path, UNIT, at, *p)?;
                let w = world.transform_point3(p);
                corners.push(check_point(self.path, UNIT, at, w.to_array())?);
            }
            if mirror {
                corners.reverse();
            }
            self.out.polygon(group, material, at, &corners);
        }
        Ok(())
    }

    /// The bytes of each element of `acc` (`size` bytes each), after checking that all
    /// lie inside its view and the view inside its buffer.
    fn accessor<'a>(
        &'a self,
        acc: &::gltf::Accessor<'_>,
        size: usize,
    ) -> Result<impl Iterator<Item = &'a [u8]> + 'a, SceneError> {
        let name = format!("accessor {}", acc.index());
        if acc.sparse().is_some() {
            return Err(self.err(name, "sparse accessors are not read".into()));
        }
        let view = acc
            .view()
            .ok_or_else(|| self.err(name.clone(), "has no buffer view".into()))?;
        let data = &self.buffers[view.buffer().index()];
        let view_end = view.offset().checked_add(view.length());
        let Some(view_bytes) = view_end.and_then(|end| data.get(view.offset()..end)) else {
            return Err(self.err(
                format!("buffer view {}", view.index()),
                format!(
                    "bytes {}..+{} lie outside buffer {} ({} bytes)",
                    view.offset(),
                    view.length(),
                    view.buffer().index(),
                    data.len()
                ),
            ));
        };
        let stride = view.stride().unwrap_or(size).max(size);
        let count = acc.count();
        let need = match count {
            0 => Some(0),
            c => (c - 1)
                .checked_mul(stride)
                .and_then(|x| x.checked_add(size))
                .and_then(|x| x.checked_add(acc.offset())),
        };
        if need.is_none_or(|n| n > view_bytes.len()) {
            return Err(self.err(
                name,
                format!(
                    "{count} elements of {size} bytes (stride {stride}, offset {}) do not fit in buffer view {} ({} bytes)",
                    acc.offset(),
                    view.index(),
                    view_bytes.len()
                ),
            ));
        }
        let start = acc.offset();
        Ok((0..count).map(move |k| &view_bytes[start + k * stride..start + k * stride + size]))
    }

    /// The scene material of a primitive (see the module docs for the precedence).
    fn material(&mut self, prim: &::gltf::Primitive<'_>, group: &str) -> Result<u32, SceneError> {
        let m = prim.material();
        let own = match m.index() {
            None => None,
            Some(k) => Some(match self.materials.get(&k) {
                Some(&id) => id,
                None => self.convert(&m, k)?,
            }),
        };
        Ok(self.out.material_for(group, own))
    }

    /// A glTF material as a scene material (added to the scene).
    fn convert(&mut self, m: &::gltf::Material<'_>, k: usize) -> Result<u32, SceneError> {
        {
            let name = m
                .name()
                .map(str::to_owned)
                .unwrap_or_else(|| format!("material{k}"));
            let here = format!("material {k} (`{name}`)");
            let base = m.pbr_metallic_roughness().base_color_factor();
            let mut rho = [base[0], base[1], base[2]];
            // Refused as the MTL loader refuses a negative Kd or Ke: a sign error in
            // the file, not a colour (they were clamped to 0 without a word).
            if let Some(x) = rho.iter().find(|&&x| !(x.is_finite() && x >= 0.0)) {
                return Err(self.err(here, format!("baseColorFactor {x} must be finite and >= 0")));
            }
            if rho.iter().any(|&x| x > MAX_KD) {
                self.out.warn(format!(
                    "{}: material `{name}`: baseColorFactor above {MAX_KD} read as {MAX_KD} (a reflectance of 1 keeps all light)",
                    self.path.display()
                ));
                rho = rho.map(|x| x.min(MAX_KD));
            }
            let strength = m.emissive_strength().unwrap_or(1.0);
            if !(strength.is_finite() && strength >= 0.0) {
                return Err(self.err(
                    here,
                    format!("emissive strength {strength} must be finite and >= 0"),
                ));
            }
            let factor = m.emissive_factor();
            if let Some(e) = factor.iter().find(|&&e| !(e.is_finite() && e >= 0.0)) {
                return Err(self.err(here, format!("emissiveFactor {e} must be finite and >= 0")));
            }
            let emission = factor.map(|e| e * strength);
            if emission.iter().any(|e| !e.is_finite()) {
                return Err(self.err(
                    here,
                    format!("emissiveFactor × emissive strength {strength} is not finite"),
                ));
            }
            let id = self.out.own_material(Material {
                name,
                rho,
                emission,
            });
            self.materials.insert(k, id);
            Ok(id)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// "glTF" is Z2xURg== in base64 (RFC 4648: 0x67 0x6c 0x54 0x46).
    #[test]
    fn data_uris_decode_padded_or_not_in_any_case_and_refuse_the_rest() {
        for uri in [
            "application/octet-stream;base64,Z2xURg==",
            "application/gltf-buffer;BASE64,Z2xURg",
            ";base64,Z2xURg==\n",
        ] {
            assert_eq!(data_uri(uri).as_deref(), Ok(&b"glTF"[..]), "{uri}");
        }
        for (uri, why) in [
            ("application/octet-stream,glTF", "is not base64"),
            (
                "application/octet-stream;base64,Z2x@Rg==",
                "not valid base64",
            ),
            ("application/octet-stream;base64", "without the comma"),
            ("é;base64é,Z2xURg==", "is not base64"),
        ] {
            let e = data_uri(uri).unwrap_err();
            assert!(e.contains(why), "{uri}: {e}");
        }
    }

    #[test]
    fn relative_uris_have_their_escapes_decoded() {
        let p = |s: &str| std::path::PathBuf::from(s);
        assert_eq!(percent_decoded("box%20data.bin"), p("box data.bin"));
        assert_eq!(percent_decoded("a%C3%A9b.bin"), p("aéb.bin"));
        // Not an escape: kept as written.
        assert_eq!(percent_decoded("100%.bin"), p("100%.bin"));
        assert_eq!(percent_decoded("x%4"), p("x%4"));
        assert_eq!(percent_decoded("x%zz"), p("x%zz"));
        // A name that is not UTF-8 (Latin-1 é) keeps its byte.
        #[cfg(unix)]
        {
            use std::os::unix::ffi::OsStrExt;
            let got = percent_decoded("caf%E9.bin");
            assert_eq!(got.as_os_str().as_bytes(), b"caf\xe9.bin");
        }
    }
}
