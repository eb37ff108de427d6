//! The patches as a VTK unstructured grid (`.vtu`, VTK's XML format) with one value per
//! patch as cell data: what ParaView, VisIt and Python's `meshio` open (uDALES users
//! look at their results in ParaView). `export --vtu` writes the matrix side (row sums,
//! sky view factors, dropped mass), `solve --vtu` the radiosity and the same matrix side.
//!
//! Cell k is patch k (a `VTK_TRIANGLE` or `VTK_QUAD`) with its own corners: points are
//! not welded, so no value is shared or averaged between patches, and the points of
//! cell k are points 3k.. or 4k.. in order. Written through the `vtkio` crate
//! (base64 binary arrays, no compression); the whole file is built in memory (about
//! 150 bytes a patch plus 12 a value), then written beside the target and renamed into
//! place, so a failed write leaves no partial grid.

use std::path::{Path, PathBuf};

use vtkio::model::{
    Attribute, Attributes, ByteOrder, CellType, Cells, DataSet, Piece, UnstructuredGridPiece,
    Version, VertexNumbers, Vtk,
};

use crate::patch::PatchSet;

/// A failed `.vtu` write, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: write VTK unstructured grid: {cause}")]
pub struct VtuError {
    pub path: PathBuf,
    pub cause: String,
}

/// One cell array: `components` values per patch, patch after patch.
#[derive(Clone, Debug, PartialEq)]
pub struct CellArray {
    pub name: &'static str,
    pub components: u32,
    pub values: CellValues,
}

/// The values of a [`CellArray`], in the precision they were computed in.
#[derive(Clone, Debug, PartialEq)]
pub enum CellValues {
    F32(Vec<f32>),
    F64(Vec<f64>),
    U32(Vec<u32>),
}

impl CellValues {
    fn len(&self) -> usize {
        match self {
            CellValues::F32(v) => v.len(),
            CellValues::F64(v) => v.len(),
            CellValues::U32(v) => v.len(),
        }
    }
}

impl CellArray {
    /// A 1-component array.
    pub fn scalar(name: &'static str, values: CellValues) -> Self {
        CellArray {
            name,
            components: 1,
            values,
        }
    }

    /// A 3-component (RGB) array from one `[r, g, b]` per patch.
    pub fn rgb_f64(name: &'static str, rgb: impl IntoIterator<Item = [f64; 3]>) -> Self {
        CellArray {
            name,
            components: 3,
            values: CellValues::F64(rgb.into_iter().flatten().collect()),
        }
    }

    /// As [`CellArray::rgb_f64`], in single precision.
    pub fn rgb_f32(name: &'static str, rgb: impl IntoIterator<Item = [f32; 3]>) -> Self {
        CellArray {
            name,
            components: 3,
            values: CellValues::F32(rgb.into_iter().flatten().collect()),
        }
    }
}

/// The arrays every grid carries: `patch` (its 0-based index, the matrix row) and
/// `group` (index into the file's group names, in order of first appearance).
pub fn patch_arrays(patches: &PatchSet) -> Vec<CellArray> {
    vec![
        CellArray::scalar(
            "patch",
            CellValues::U32((0..patches.len() as u32).collect()),
        ),
        CellArray::scalar(
            "group",
            CellValues::U32(patches.patches.iter().map(|p| p.group).collect()),
        ),
        CellArray::scalar(
            "area",
            CellValues::F64(patches.patches.iter().map(|p| p.area).collect()),
        ),
    ]
}

/// Write `patches` as an unstructured grid with `arrays` as cell data.
///
/// A caller bug panics: an array whose length is not components × patches.
///
/// # Errors
/// [`VtuError`] naming `path` when the grid cannot be encoded or written.
pub fn write_vtu(path: &Path, patches: &PatchSet, arrays: Vec<CellArray>) -> Result<(), VtuError> {
    let err = |cause: String| VtuError {
        path: path.to_owned(),
        cause,
    };
    let n = patches.len();
    let mut points = Vec::with_capacity(n * 12);
    let mut connectivity = Vec::with_capacity(n * 4);
    let mut offsets = Vec::with_capacity(n);
    let mut types = Vec::with_capacity(n);
    for p in &patches.patches {
        let k = p.n_corners as usize;
        for c in &p.corners[..k] {
            connectivity.push((points.len() / 3) as u64);
            points.extend(c.to_array());
        }
        offsets.push(connectivity.len() as u64);
        types.push(if k == 3 {
            CellType::Triangle
        } else {
            CellType::Quad
        });
    }
    let cell = arrays
        .into_iter()
        .map(|a| {
            assert_eq!(
                a.values.len(),
                a.components as usize * n,
                "cell array {} has the wrong length",
                a.name
            );
            let data = Attribute::scalars(a.name, a.components);
            match a.values {
                CellValues::F32(v) => data.with_data(v),
                CellValues::F64(v) => data.with_data(v),
                CellValues::U32(v) => data.with_data(v),
            }
        })
        .collect();
    let vtk = Vtk {
        version: Version::new(),
        title: String::from("ffstream patches"),
        byte_order: ByteOrder::LittleEndian,
        file_path: None,
        data: DataSet::UnstructuredGrid {
            meta: None,
            pieces: vec![Piece::Inline(Box::new(UnstructuredGridPiece {
                points: points.into(),
                cells: Cells {
                    cell_verts: VertexNumbers::XML {
                        connectivity,
                        offsets,
                    },
                    types,
                },
                data: Attributes {
                    point: Vec::new(),
                    cell,
                },
            }))],
        },
    };
    let xml = vtkio::xml::VTKFile::try_from(vtk).map_err(|e| err(e.to_string()))?;
    let text = xml.to_string();
    if path.exists() && !path.is_file() {
        // A device (/dev/null, /dev/stdout redirected): written to, never replaced.
        return std::fs::write(path, text.as_bytes()).map_err(|e| err(e.to_string()));
    }
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.{}.partial", std::process::id()));
    let written = std::fs::write(&tmp, text.as_bytes()).and_then(|()| std::fs::rename(&tmp, path));
    written.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        err(e.to_string())
    })
}
