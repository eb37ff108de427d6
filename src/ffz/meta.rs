//! File metadata: the header fields a caller chooses ([`FileMeta`]) and the meta block
//! that carries them on disk (spec §3, §4): fixed header, method/params/created strings,
//! patch table, group name table, meta checksum.

use super::spec::{self, HeaderV1, Le, PatchRecordV1};
use crate::patch::{Patch, PatchSet};
use glam::DVec3;

/// How rows are stored (spec §3.1 `layout`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Layout {
    /// Every row holds all n values.
    Dense,
    /// Every row holds at most k (column, value) pairs plus the dropped mass.
    TopK { k: u32 },
}

impl Layout {
    /// (layout code, k) as stored in the header.
    pub(crate) fn to_code(self) -> (u32, u32) {
        match self {
            Layout::Dense => (spec::LAYOUT_DENSE, 0),
            Layout::TopK { k } => (spec::LAYOUT_TOPK, k),
        }
    }

    /// Inverse of [`Layout::to_code`] (the header decoder has validated the pair).
    pub(crate) fn from_code(code: u32, k: u32) -> Option<Layout> {
        match code {
            spec::LAYOUT_DENSE => Some(Layout::Dense),
            spec::LAYOUT_TOPK if k > 0 => Some(Layout::TopK { k }),
            _ => None,
        }
    }

    pub(crate) fn is_sparse(self) -> bool {
        matches!(self, Layout::TopK { .. })
    }
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Layout::Dense => write!(f, "dense"),
            Layout::TopK { k } => write!(f, "top-k (k = {k})"),
        }
    }
}

/// Everything the header and the patch table hold, as the writer is given it and the
/// reader returns it. `n = patches.len()`.
#[derive(Clone, Debug, PartialEq)]
pub struct FileMeta {
    pub layout: Layout,
    /// Form-factor method ("point", "mc", "contour", ...).
    pub method: String,
    /// Method parameters as one string ("samples=16 seed=0 ...").
    pub params: String,
    /// Scene hash ([`PatchSet::content_hash`]); `resume` refuses a different one.
    pub scene_hash: u64,
    /// Creation info (time, program version, host), free text.
    pub created: String,
    pub patches: PatchSet,
    /// The cluster order of a file whose rows link to clusters (spec §4.3): a
    /// permutation of the patches, in which every cluster is a range of positions.
    pub clusters: Option<Vec<u32>>,
}

impl FileMeta {
    /// Number of rows and columns.
    pub fn n(&self) -> u32 {
        self.patches.len() as u32
    }
}

/// Encode the whole meta block (spec §3: header, strings, §4 patch table, group
/// names, meta checksum). The block's length is the offset of the first chunk.
///
/// # Errors
/// `InvalidMeta` when n does not fit u32, a patch names a group that does not exist or
/// has 3 or 4 corners, or a string is longer than u32.
pub(crate) fn encode_meta(meta: &FileMeta, zstd_level: i32) -> Result<Vec<u8>, super::FfzError> {
    use super::FfzError::InvalidMeta;
    let n = u32::try_from(meta.patches.len()).map_err(|_| {
        InvalidMeta(format!(
            "{} patches do not fit a u32 row index",
            meta.patches.len()
        ))
    })?;
    let len32 = |s: &str, what: &str| {
        u32::try_from(s.len()).map_err(|_| InvalidMeta(format!("{what} string longer than 4 GiB")))
    };
    let (layout, k) = meta.layout.to_code();
    if meta.layout == (Layout::TopK { k: 0 }) {
        return Err(InvalidMeta("top-k layout with k = 0".into()));
    }
    let n_groups = u32::try_from(meta.patches.groups.len())
        .map_err(|_| InvalidMeta("too many groups".into()))?;
    let mut body = Vec::with_capacity(meta.patches.len() * spec::PATCH_RECORD_LEN + 256);
    body.extend_from_slice(meta.method.as_bytes());
    body.extend_from_slice(meta.params.as_bytes());
    body.extend_from_slice(meta.created.as_bytes());
    for (i, p) in meta.patches.patches.iter().enumerate() {
        if p.n_corners != 3 && p.n_corners != 4 {
            return Err(InvalidMeta(format!(
                "patch {i} has {} corners (3 or 4 allowed)",
                p.n_corners
            )));
        }
        if p.group >= n_groups {
            return Err(InvalidMeta(format!(
                "patch {i} refers to group {} but there are {n_groups} groups",
                p.group
            )));
        }
        PatchRecordV1 {
            n_corners: p.n_corners as u32,
            group: p.group,
            face: p.face,
            corners: p.corners.map(|c| c.to_array()),
            normal: p.normal.to_array(),
            area: p.area,
            rho: p.rho,
            emission: p.emission,
        }
        .encode_into(&mut body);
    }
    body.extend_from_slice(&n_groups.to_le_bytes());
    for g in &meta.patches.groups {
        body.extend_from_slice(&len32(g, "group name")?.to_le_bytes());
        body.extend_from_slice(g.as_bytes());
    }
    if let Some(order) = &meta.clusters {
        if !meta.layout.is_sparse() {
            return Err(InvalidMeta(
                "a cluster order without the top-k layout".into(),
            ));
        }
        check_cluster_order(order, n).map_err(InvalidMeta)?;
        for &p in order {
            body.extend_from_slice(&p.to_le_bytes());
        }
    }
    let meta_crc = spec::crc(&body);
    body.extend_from_slice(&meta_crc.to_le_bytes());
    let header = HeaderV1 {
        flags: match meta.clusters {
            Some(_) => spec::HEADER_FLAG_CLUSTERS,
            None => 0,
        },
        n,
        layout,
        k,
        zstd_level,
        scene_hash: meta.scene_hash,
        meta_len: (spec::HEADER_LEN + body.len()) as u64,
        method_len: len32(&meta.method, "method")?,
        params_len: len32(&meta.params, "params")?,
        created_len: len32(&meta.created, "created")?,
    };
    let mut out = Vec::with_capacity(spec::HEADER_LEN + body.len());
    out.extend_from_slice(&header.encode());
    out.extend_from_slice(&body);
    Ok(out)
}

/// Spec §4.3: the cluster order holds every patch index below n exactly once.
pub(crate) fn check_cluster_order(order: &[u32], n: u32) -> Result<(), String> {
    if order.len() != n as usize {
        return Err(format!("cluster order of {} patches, n = {n}", order.len()));
    }
    let mut seen = vec![false; n as usize];
    for (k, &p) in order.iter().enumerate() {
        match seen.get_mut(p as usize) {
            None => {
                return Err(format!(
                    "cluster order position {k} holds patch {p} ≥ n = {n}"
                ))
            }
            Some(true) => return Err(format!("cluster order holds patch {p} twice")),
            Some(s) => *s = true,
        }
    }
    Ok(())
}

/// Decode the fixed header from the first 64 bytes. `Err` holds (offset, reason); magic
/// and version faults are reported by the caller, which has the path.
pub(crate) fn decode_header(bytes: &[u8]) -> Result<HeaderV1, spec::Fault> {
    let Some(b) = bytes.get(..spec::HEADER_LEN) else {
        return Err((
            0,
            format!(
                "file has {} bytes, shorter than the 64-byte header",
                bytes.len()
            ),
        ));
    };
    let mut arr = [0u8; spec::HEADER_LEN];
    arr.copy_from_slice(b);
    HeaderV1::decode(&arr)
}

/// The meta block's body (after the header, before the checksum), once its length is
/// checked against the header's and its CRC-32C against the stored one.
fn meta_body<'a>(bytes: &'a [u8], header: &HeaderV1) -> Result<&'a [u8], spec::Fault> {
    let meta_len =
        usize::try_from(header.meta_len).map_err(|_| (40, "meta_len too large".to_string()))?;
    let min = spec::HEADER_LEN as u64
        + header.method_len as u64
        + header.params_len as u64
        + header.created_len as u64
        + header.n as u64 * spec::PATCH_RECORD_LEN as u64
        + 8;
    if (meta_len as u64) < min {
        return Err((
            40,
            format!("meta_len {meta_len} is shorter than its contents need ({min})"),
        ));
    }
    let Some(block) = bytes.get(..meta_len) else {
        return Err((
            bytes.len() as u64,
            format!(
                "file ends at byte {} inside the meta block (meta_len {meta_len})",
                bytes.len()
            ),
        ));
    };
    let body = &block[spec::HEADER_LEN..meta_len - 4];
    let stored = u32::from_le_bytes(block[meta_len - 4..].try_into().unwrap_or_default());
    let actual = spec::crc(body);
    if stored != actual {
        return Err((
            meta_len as u64 - 4,
            format!(
                "meta block checksum mismatch (stored {stored:#010x}, computed {actual:#010x})"
            ),
        ));
    }
    Ok(body)
}

/// Decode the meta block that follows the header (spec §3.2 to §4.3). `bytes` is the
/// whole file prefix (at least `header.meta_len` bytes). `Err` holds (file offset, reason).
pub(crate) fn decode_meta(bytes: &[u8], header: &HeaderV1) -> Result<FileMeta, spec::Fault> {
    let body = meta_body(bytes, header)?;
    let base = spec::HEADER_LEN as u64;
    let mut r = Le::new(body);
    let at = |r: &Le<'_>| base + r.pos() as u64;
    let string = |r: &mut Le<'_>, len: u32, what: &str| -> Result<String, spec::Fault> {
        let off = at(r);
        let b = r
            .take(len as usize)
            .ok_or((off, format!("{what} string cut short")))?;
        String::from_utf8(b.to_vec()).map_err(|_| (off, format!("{what} string is not UTF-8")))
    };
    let method = string(&mut r, header.method_len, "method")?;
    let params = string(&mut r, header.params_len, "params")?;
    let created = string(&mut r, header.created_len, "created")?;
    let mut patches = Vec::with_capacity(header.n as usize);
    for i in 0..header.n {
        let off = at(&r);
        let rec = r
            .take(spec::PATCH_RECORD_LEN)
            .ok_or((off, format!("patch {i} cut short")))?;
        let p =
            PatchRecordV1::decode(rec).map_err(|(o, w)| (off + o, format!("patch {i}: {w}")))?;
        patches.push(Patch {
            corners: p.corners.map(DVec3::from_array),
            n_corners: p.n_corners as u8,
            normal: DVec3::from_array(p.normal),
            area: p.area,
            group: p.group,
            face: p.face,
            rho: p.rho,
            emission: p.emission,
        });
    }
    let off = at(&r);
    let n_groups = r.u32().ok_or((off, "group table cut short".to_string()))?;
    let mut groups = Vec::new();
    for g in 0..n_groups {
        let off = at(&r);
        let len = r.u32().ok_or((off, format!("group {g} name cut short")))?;
        groups.push(string(&mut r, len, "group name")?);
    }
    let clusters = match header.flags & spec::HEADER_FLAG_CLUSTERS {
        0 => None,
        _ => {
            let off = at(&r);
            let bytes = r
                .take(4 * header.n as usize)
                .ok_or((off, "cluster order cut short".to_string()))?;
            let order: Vec<u32> = bytes
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            check_cluster_order(&order, header.n).map_err(|w| (off, w))?;
            Some(order)
        }
    };
    if r.pos() != body.len() {
        return Err((
            at(&r),
            format!(
                "{} unexplained bytes before the meta checksum",
                body.len() - r.pos()
            ),
        ));
    }
    for (i, p) in patches.iter().enumerate() {
        if p.group >= n_groups {
            return Err((
                base + header.method_len as u64
                    + header.params_len as u64
                    + header.created_len as u64
                    + (i * spec::PATCH_RECORD_LEN) as u64
                    + 4,
                format!("patch {i} refers to group {} of {n_groups}", p.group),
            ));
        }
    }
    let layout =
        Layout::from_code(header.layout, header.k).ok_or((20, "bad layout".to_string()))?;
    Ok(FileMeta {
        layout,
        method,
        params,
        scene_hash: header.scene_hash,
        created,
        patches: PatchSet { patches, groups },
        clusters,
    })
}
