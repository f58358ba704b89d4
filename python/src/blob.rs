//! `hamflight.Blob` and `hamflight.BlobError`: the checked weight-blob codec of the core.

use std::path::PathBuf;
use std::sync::Arc;

use hamflight::blob::{self, BlobError as CoreBlobError, CRC_LEN, HEADER_LEN};
use hamflight::model::LearnedModel;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};

pyo3::create_exception!(
    _core,
    BlobError,
    PyValueError,
    "A weight blob was rejected (a ValueError); `kind` names the failed check: Truncated,\n\
     BadMagic, UnsupportedVersion, ShapeMismatch, Checksum, TrailingBytes, Malformed, NonFinite,\n\
     BadMass, BadMotorTau, BadPort. The message names the file and the problem."
);

/// The shipped blob (`weights/default.hfw` when this package was built).
pub const DEFAULT_BLOB: &[u8] = include_bytes!("../../weights/default.hfw");

fn kind(e: &CoreBlobError) -> &'static str {
    match e {
        CoreBlobError::Truncated => "Truncated",
        CoreBlobError::BadMagic => "BadMagic",
        CoreBlobError::UnsupportedVersion(_) => "UnsupportedVersion",
        CoreBlobError::ShapeMismatch => "ShapeMismatch",
        CoreBlobError::Checksum => "Checksum",
        CoreBlobError::TrailingBytes => "TrailingBytes",
        CoreBlobError::Malformed => "Malformed",
        CoreBlobError::NonFinite => "NonFinite",
        CoreBlobError::BadMass => "BadMass",
        CoreBlobError::BadMotorTau => "BadMotorTau",
        CoreBlobError::BadPort(_) => "BadPort",
    }
}

/// The core's error as a `BlobError` with `kind` set; `origin` names the file when there is one.
pub fn blob_err(py: Python<'_>, e: &CoreBlobError, origin: Option<&str>) -> PyErr {
    let msg = match origin {
        Some(o) => format!("{o}: {e} ({})", kind(e)),
        None => format!("{e} ({})", kind(e)),
    };
    let err = BlobError::new_err(msg);
    let _ = err.value(py).setattr("kind", kind(e));
    err
}

/// The bytes `w` names: bytes-like, or a path (str / os.PathLike) to read.
fn bytes_of(w: &Bound<'_, PyAny>) -> PyResult<(Vec<u8>, String)> {
    if let Ok(b) = w.cast::<PyBytes>() {
        return Ok((b.as_bytes().to_vec(), "<bytes>".into()));
    }
    if let Ok(b) = w.extract::<Vec<u8>>() {
        if !w.is_instance_of::<pyo3::types::PyString>() {
            return Ok((b, "<bytes>".into()));
        }
    }
    let path: PathBuf = w.extract().map_err(|_| {
        PyTypeError::new_err(format!(
            "weights: expected a path, bytes or a hamflight.Blob, got {}",
            w.get_type()
        ))
    })?;
    let path = crate::packaged_or(w.py(), path, "weights");
    let bytes = std::fs::read(&path).map_err(|e| {
        pyo3::exceptions::PyOSError::new_err(format!(
            "cannot read weight blob `{}`: {e}",
            path.display()
        ))
    })?;
    Ok((bytes, path.display().to_string()))
}

/// A learned model from a path or bytes, the error naming the problem.
pub fn model_from_weights(w: &Bound<'_, PyAny>) -> PyResult<LearnedModel> {
    let (bytes, origin) = bytes_of(w)?;
    LearnedModel::from_blob(&bytes).map_err(|e| blob_err(w.py(), &e, Some(&origin)))
}

/// The shipped model.
pub fn default_model() -> PyResult<Arc<LearnedModel>> {
    LearnedModel::from_blob(DEFAULT_BLOB)
        .map(Arc::new)
        .map_err(|e| PyValueError::new_err(format!("the built-in blob: {e}")))
}

/// A checked weight blob: the learned model's networks and the vehicle's mass.
///
/// `Blob.load(path)`, `Blob.from_bytes(data)` or `Blob.default()`; a rejected blob raises
/// `BlobError`. A `Controller` takes one (or its path or bytes) as `weights`. Blobs compare by
/// their bytes (`==`, `hash` is the CRC) and pickle as them.
#[pyclass(module = "hamflight._core", frozen)]
pub struct Blob {
    pub model: Arc<LearnedModel>,
    bytes: Vec<u8>,
    name: String,
}

impl Blob {
    fn from_parts(py: Python<'_>, bytes: Vec<u8>, name: String) -> PyResult<Self> {
        let model = LearnedModel::from_blob(&bytes).map_err(|e| blob_err(py, &e, Some(&name)))?;
        Ok(Self {
            model: Arc::new(model),
            bytes,
            name,
        })
    }
}

#[pymethods]
impl Blob {
    /// Reads and checks a blob file (str or os.PathLike); raises BlobError (or OSError) naming
    /// the problem. A relative `weights/default.hfw` that does not exist is the package's copy
    /// (`hamflight.data`).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let path = crate::packaged_or(py, path, "weights");
        let bytes = std::fs::read(&path).map_err(|e| {
            pyo3::exceptions::PyOSError::new_err(format!(
                "cannot read weight blob `{}`: {e}",
                path.display()
            ))
        })?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string());
        Self::from_parts(py, bytes, name)
    }

    /// Checks a blob held in memory; `name` is what `name` and the errors call it.
    #[staticmethod]
    #[pyo3(signature = (data, name="<bytes>"))]
    fn from_bytes(py: Python<'_>, data: Vec<u8>, name: &str) -> PyResult<Self> {
        Self::from_parts(py, data, name.to_owned())
    }

    /// The blob shipped with this package (the repository's weights/default.hfw).
    #[staticmethod]
    fn default(py: Python<'_>) -> PyResult<Self> {
        Self::from_parts(py, DEFAULT_BLOB.to_vec(), "default.hfw".into())
    }

    /// Raises BlobError (its `kind` names the failed check) unless `data` is a valid blob.
    #[staticmethod]
    fn validate(py: Python<'_>, data: Vec<u8>) -> PyResult<()> {
        blob::decode(&data)
            .map(|_| ())
            .map_err(|e| blob_err(py, &e, None))
    }

    /// The vehicle mass the blob carries (kg).
    #[getter]
    fn mass_kg(&self) -> f32 {
        self.model.weights.mass_kg
    }

    /// The file name it was loaded from (or the name given to from_bytes).
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// The body's CRC-32 as stored in the blob (what the Crazyflie app's console prints).
    #[getter]
    fn crc(&self) -> u32 {
        let n = self.bytes.len();
        let mut b = [0u8; 4];
        b.copy_from_slice(&self.bytes[n - CRC_LEN..]);
        u32::from_le_bytes(b)
    }

    /// The format version in the header.
    #[getter]
    fn version(&self) -> u16 {
        u16::from_le_bytes([self.bytes[4], self.bytes[5]])
    }

    /// The number of network parameters.
    #[getter]
    fn params(&self) -> usize {
        hamflight::model::ModelWeights::PARAMS
    }

    /// The blob's bytes as loaded (`Blob.from_bytes(b.to_bytes()) == b`).
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.bytes)
    }

    /// The weights encoded afresh by the core's encoder (the current format version).
    fn encode<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &blob::encode(&self.model.weights))
    }

    /// A copy with another vehicle mass (kg), re-encoded and checked.
    fn with_mass(&self, py: Python<'_>, mass_kg: f32) -> PyResult<Self> {
        let mut w = self.model.weights;
        w.mass_kg = mass_kg;
        Self::from_parts(py, blob::encode(&w), self.name.clone())
    }

    /// Pickling (and `copy`, multiprocessing, Ray): the bytes as loaded and the name, checked
    /// again on unpickling.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let restore = py.import("hamflight._core")?.getattr("_restore_blob")?;
        let args = (PyBytes::new(py, &self.bytes), self.name.as_str()).into_pyobject(py)?;
        PyTuple::new(py, [restore, args.into_any()])
    }

    /// The blob's size in bytes.
    fn __len__(&self) -> usize {
        self.bytes.len()
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .cast::<Blob>()
            .map(|o| o.get().bytes == self.bytes)
            .unwrap_or(false)
    }

    fn __hash__(&self) -> u64 {
        u64::from(self.crc())
    }

    fn __repr__(&self) -> String {
        format!(
            "Blob(name={:?}, mass_kg={}, crc=0x{:08x}, version={}, bytes={})",
            self.name,
            self.mass_kg(),
            self.crc(),
            self.version(),
            self.bytes.len()
        )
    }
}

/// Unpickles a `Blob` (`Blob.__reduce__`).
#[pyfunction]
pub fn _restore_blob(py: Python<'_>, data: Vec<u8>, name: String) -> PyResult<Blob> {
    Blob::from_parts(py, data, name)
}

/// The header and trailer sizes (for tests that corrupt blobs on purpose).
pub const LAYOUT: (usize, usize) = (HEADER_LEN, CRC_LEN);
