//! `.npy` files: typed arrays with checked shapes and dtypes, written atomically.
//!
//! The header is read and written by `npyz`; the data is the little-endian bytes of the
//! records themselves, so a write followed by a read gives identical bytes. A record with one
//! field is stored as a plain array (`tran.npy` is `(N, 4, 4) float64`); a record with several
//! fields as a structured array whose field names are the Rust field names.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

use npyz::{DType, Field as NpyField, TypeStr, WriterBuilder};

use crate::error::{FoundryError, Result};
use crate::layout::{Record, Scalar};

/// An array read from a `.npy` file: element type, shape and raw little-endian bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Element type.
    pub scalar: Scalar,
    /// Shape, outermost first (C order).
    pub shape: Vec<u64>,
    /// The data, `shape.product() * scalar.size()` bytes.
    pub bytes: Vec<u8>,
}

fn plain(scalar: Scalar) -> DType {
    DType::Plain(
        scalar
            .numpy()
            .parse::<TypeStr>()
            .expect("valid type string"),
    )
}

fn scalar_of(dtype: &DType) -> Option<Scalar> {
    let DType::Plain(ty) = dtype else { return None };
    [Scalar::F32, Scalar::F64, Scalar::U32, Scalar::I32]
        .into_iter()
        .find(|s| ty.to_string() == s.numpy())
}

/// The dtype and per-record shape under which records of type `R` are stored.
pub fn record_dtype<R: Record>() -> (DType, Vec<u64>) {
    match R::fields() {
        [single] => (
            plain(single.scalar),
            single.shape.iter().map(|&n| n as u64).collect(),
        ),
        fields => {
            let fields = fields
                .iter()
                .map(|f| NpyField {
                    name: f.name.to_string(),
                    dtype: f.shape.iter().rev().fold(plain(f.scalar), |inner, &n| {
                        DType::Array(n as u64, Box::new(inner))
                    }),
                })
                .collect();
            (DType::Record(fields), Vec::new())
        }
    }
}

/// The temporary files and directories being written now: an interrupt handler removes them
/// with [`remove_temporaries`], since an interrupted process runs no destructors.
static TEMPORARIES: std::sync::Mutex<Vec<std::path::PathBuf>> = std::sync::Mutex::new(Vec::new());

/// A temporary file or directory being written, listed for [`remove_temporaries`] while this
/// value lives (drop it once the temporary is gone or in place).
#[derive(Debug)]
pub struct TrackedTemporary(std::path::PathBuf);

impl TrackedTemporary {
    /// Lists `path`.
    pub fn new(path: &Path) -> Self {
        let mut list = TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner());
        list.push(path.to_path_buf());
        TrackedTemporary(path.to_path_buf())
    }
}

impl Drop for TrackedTemporary {
    fn drop(&mut self) {
        let mut list = TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(at) = list.iter().position(|p| *p == self.0) {
            list.swap_remove(at);
        }
    }
}

/// Removes every temporary file and directory being written (for an interrupt handler: the
/// command then leaves no partial output behind).
pub fn remove_temporaries() {
    let list = TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner());
    for p in list.iter() {
        let _ = if p.is_dir() {
            std::fs::remove_dir_all(p)
        } else {
            std::fs::remove_file(p)
        };
    }
}

/// A new temporary file (named `.hytrace-*`) in `path`'s directory, to be renamed onto
/// `path` once written; missing parent directories are created, as for `hytrace foundry -o`.
pub fn temporary_beside(path: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    tempfile::Builder::new()
        .prefix(".hytrace-")
        .tempfile_in(dir)
}

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename, so
/// `path` never holds a partial file. Missing parent directories are created.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let io_err = |source| FoundryError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut tmp = temporary_beside(path).map_err(io_err)?;
    let _tracked = TrackedTemporary::new(tmp.path());
    {
        let mut w = BufWriter::new(tmp.as_file_mut());
        write(&mut w).map_err(io_err)?;
        w.flush().map_err(io_err)?;
    }
    // Temporary files are created private (0600); the result is an ordinary file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644))
            .map_err(io_err)?;
    }
    tmp.persist(path).map_err(|e| io_err(e.error))?;
    Ok(())
}

fn write_with_header(path: &Path, dtype: DType, shape: &[u64], bytes: &[u8]) -> Result<()> {
    write_atomically(path, |w| {
        let w = npyz::WriteOptions::new_header_only()
            .dtype(dtype)
            .shape(shape)
            .writer(w)
            .write_header_only()?;
        w.write_all(bytes)
    })
}

/// Writes a plain array of `scalar` elements with the given shape.
pub fn write_array(path: &Path, scalar: Scalar, shape: &[u64], bytes: &[u8]) -> Result<()> {
    let expected = shape.iter().product::<u64>() * scalar.size() as u64;
    if expected != bytes.len() as u64 {
        return Err(FoundryError::Build(format!(
            "{}: shape {shape:?} needs {expected} bytes, got {}",
            path.display(),
            bytes.len()
        )));
    }
    write_with_header(path, plain(scalar), shape, bytes)
}

/// Writes records as `(N, ...)` plain or `(N,)` structured arrays (see the module docs).
pub fn write_records<R: Record>(path: &Path, records: &[R]) -> Result<()> {
    let (dtype, per_record) = record_dtype::<R>();
    let mut shape = vec![records.len() as u64];
    shape.extend(per_record);
    write_with_header(path, dtype, &shape, bytemuck::cast_slice(records))
}

/// Bytes of the header an [`NpyStream`] writes: fixed, so the final shape fits where the
/// first one was (a multiple of 64, as NumPy aligns its headers).
const STREAM_HEADER: usize = 128;

/// A plain `.npy` array written row by row, its shape `(rows, ...)` filled in when it is
/// finished: for outputs larger than memory. The file is written where it is created
/// (give it a temporary path and rename it, as [`write_atomically`] does, to keep readers
/// from a partial file).
#[derive(Debug)]
pub struct NpyStream {
    file: BufWriter<File>,
    path: std::path::PathBuf,
    /// NumPy's type string of the elements (`<f8`, `<u8`, ...) and their size in bytes.
    descr: String,
    item: usize,
    /// The shape of one row.
    row: Vec<u64>,
    rows: u64,
}

impl NpyStream {
    /// Creates `path` for rows of shape `row` of elements of NumPy type `descr` (a
    /// little-endian plain type such as `<f8` or `<u8`), `item` bytes each.
    pub fn create(path: &Path, descr: &str, item: usize, row: &[u64]) -> Result<Self> {
        let file = File::create(path).map_err(|source| FoundryError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut stream = NpyStream {
            file: BufWriter::new(file),
            path: path.to_path_buf(),
            descr: descr.to_string(),
            item,
            row: row.to_vec(),
            rows: 0,
        };
        let header = stream.header();
        stream.write(&header)?;
        Ok(stream)
    }

    /// The header for the rows written so far.
    fn header(&self) -> Vec<u8> {
        let mut shape: Vec<String> = vec![self.rows.to_string()];
        shape.extend(self.row.iter().map(u64::to_string));
        let shape = match shape.len() {
            1 => format!("({},)", shape[0]),
            _ => format!("({})", shape.join(", ")),
        };
        let dict = format!(
            "{{'descr': '{}', 'fortran_order': False, 'shape': {shape}, }}",
            self.descr
        );
        let mut h = b"\x93NUMPY\x01\x00".to_vec();
        h.extend(((STREAM_HEADER - 10) as u16).to_le_bytes());
        h.extend(dict.as_bytes());
        h.resize(STREAM_HEADER - 1, b' ');
        h.push(b'\n');
        h
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.file
            .write_all(bytes)
            .map_err(|source| FoundryError::Io {
                path: self.path.clone(),
                source,
            })
    }

    /// Appends `bytes`, a whole number of rows.
    pub fn append(&mut self, bytes: &[u8]) -> Result<()> {
        let row_bytes = self.row.iter().product::<u64>() * self.item as u64;
        if row_bytes == 0 || !(bytes.len() as u64).is_multiple_of(row_bytes) {
            return Err(FoundryError::Build(format!(
                "{}: {} bytes are not whole rows of {row_bytes} bytes",
                self.path.display(),
                bytes.len()
            )));
        }
        self.write(bytes)?;
        self.rows += bytes.len() as u64 / row_bytes;
        Ok(())
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Writes the final shape into the header and closes the file.
    pub fn finish(mut self) -> Result<()> {
        use std::io::{Seek, SeekFrom};
        let header = self.header();
        let io = |source| FoundryError::Io {
            path: self.path.clone(),
            source,
        };
        if header.len() != STREAM_HEADER {
            return Err(FoundryError::Build(format!(
                "{}: the shape does not fit a {STREAM_HEADER}-byte header",
                self.path.display()
            )));
        }
        self.file.flush().map_err(io)?;
        let file = self.file.get_mut();
        file.seek(SeekFrom::Start(0)).map_err(io)?;
        file.write_all(&header).map_err(io)?;
        file.sync_all().map_err(io)
    }
}

struct RawNpy {
    dtype: DType,
    shape: Vec<u64>,
    bytes: Vec<u8>,
}

fn file_error(path: &Path, problem: impl Into<String>) -> FoundryError {
    FoundryError::File {
        path: path.to_path_buf(),
        problem: problem.into(),
    }
}

/// Reads the header and exactly the data bytes it announces.
fn read_raw(path: &Path) -> Result<RawNpy> {
    let file = File::open(path).map_err(|source| FoundryError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut reader = BufReader::new(file);
    let header = npyz::NpyHeader::from_reader(&mut reader)
        .map_err(|e| file_error(path, format!("not a valid .npy file: {e}")))?;
    let npy = npyz::NpyFile::with_header(header, reader);
    let dtype = npy.dtype();
    let shape = npy.shape().to_vec();
    if npy.order() != npyz::Order::C {
        return Err(file_error(
            path,
            "Fortran-ordered arrays are not supported; save with C order",
        ));
    }
    let item = dtype
        .num_bytes()
        .ok_or_else(|| file_error(path, format!("unsupported dtype {}", dtype.descr())))?;
    let expected = shape
        .iter()
        .try_fold(item as u64, |acc, &n| acc.checked_mul(n))
        .filter(|&n| n <= isize::MAX as u64)
        .ok_or_else(|| file_error(path, format!("shape {shape:?} is too large")))?;
    let file_len = std::fs::metadata(path).map(|m| m.len()).unwrap_or(u64::MAX);
    if expected > file_len {
        return Err(file_error(path, format!("truncated: shape {shape:?} needs {expected} data bytes, the file has {file_len} bytes in all")));
    }
    let mut bytes = Vec::with_capacity(expected as usize);
    let mut reader = npy.into_inner();
    reader
        .by_ref()
        .take(expected)
        .read_to_end(&mut bytes)
        .map_err(|source| FoundryError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    if (bytes.len() as u64) < expected {
        return Err(file_error(
            path,
            format!(
                "truncated: shape {shape:?} needs {expected} data bytes, found {}",
                bytes.len()
            ),
        ));
    }
    let mut extra = [0u8; 1];
    if reader.read(&mut extra).unwrap_or(0) != 0 {
        return Err(file_error(
            path,
            format!("trailing bytes after the {expected} data bytes of shape {shape:?}"),
        ));
    }
    Ok(RawNpy {
        dtype,
        shape,
        bytes,
    })
}

/// Reads a plain (non-structured) array of one of the supported scalar types.
pub fn read_array(path: &Path) -> Result<NpyArray> {
    let raw = read_raw(path)?;
    let scalar = scalar_of(&raw.dtype).ok_or_else(|| {
        file_error(
            path,
            format!(
                "dtype {} is not one of float32, float64, uint32, int32",
                raw.dtype.descr()
            ),
        )
    })?;
    Ok(NpyArray {
        scalar,
        shape: raw.shape,
        bytes: raw.bytes,
    })
}

/// Reads records written by [`write_records`] (or by NumPy with the same dtype and shape).
pub fn read_records<R: Record>(path: &Path) -> Result<Vec<R>> {
    let raw = read_raw(path)?;
    let (dtype, per_record) = record_dtype::<R>();
    if raw.dtype != dtype {
        return Err(file_error(
            path,
            format!(
                "wrong dtype for {} records: expected {}, found {}",
                R::NAME,
                dtype.descr(),
                raw.dtype.descr()
            ),
        ));
    }
    if raw.shape.len() != 1 + per_record.len() || raw.shape[1..] != per_record[..] {
        let mut want = vec!["N".to_string()];
        want.extend(per_record.iter().map(u64::to_string));
        return Err(file_error(
            path,
            format!(
                "wrong shape for {} records: expected ({}), found {:?}",
                R::NAME,
                want.join(", "),
                raw.shape
            ),
        ));
    }
    Ok(bytemuck::pod_collect_to_vec(&raw.bytes))
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_interrupt_removes_the_temporaries_being_written() {
        let dir = tempfile::tempdir().unwrap();
        let (file, sub) = (dir.path().join(".hytrace-a"), dir.path().join(".hytrace-b"));
        std::fs::write(&file, "partial").unwrap();
        std::fs::create_dir(&sub).unwrap();
        std::fs::write(sub.join("x.npy"), "partial").unwrap();
        let kept = dir.path().join("done.npy");
        std::fs::write(&kept, "whole").unwrap();
        let tracked = [
            super::TrackedTemporary::new(&file),
            super::TrackedTemporary::new(&sub),
        ];
        super::remove_temporaries();
        assert!(!file.exists() && !sub.exists() && kept.exists());
        drop(tracked);
        // Once dropped, a path is no longer removed.
        std::fs::write(&file, "written").unwrap();
        super::remove_temporaries();
        assert!(file.exists());
    }

    use super::*;
    use crate::records::{Node, Transform64};

    #[test]
    fn structured_dtype_names_every_field() {
        let (dtype, shape) = record_dtype::<Node>();
        assert!(shape.is_empty());
        let descr = dtype.descr();
        for f in Node::fields() {
            assert!(descr.contains(&format!("'{}'", f.name)), "{descr}");
        }
        assert_eq!(dtype.num_bytes(), Some(64));
        let (dtype, shape) = record_dtype::<Transform64>();
        assert_eq!(dtype.descr(), "'<f8'");
        assert_eq!(shape, vec![4, 4]);
    }

    #[test]
    fn streamed_rows_read_back_as_one_array() {
        let dir = tempfile::tempdir().unwrap();
        let (streamed, whole) = (dir.path().join("s.npy"), dir.path().join("w.npy"));
        let values: Vec<f64> = (0..60).map(|i| i as f64 * 0.5).collect();
        let mut s = NpyStream::create(&streamed, "<f8", 8, &[3, 2]).unwrap();
        for chunk in values.chunks(12) {
            s.append(bytemuck::cast_slice(chunk)).unwrap();
        }
        assert!(s.append(&[0u8; 8]).is_err());
        assert_eq!(s.rows(), 10);
        s.finish().unwrap();
        write_array(
            &whole,
            Scalar::F64,
            &[10, 3, 2],
            bytemuck::cast_slice(&values),
        )
        .unwrap();
        assert_eq!(read_array(&streamed).unwrap(), read_array(&whole).unwrap());
        // No rows, one-dimensional rows.
        let empty = dir.path().join("e.npy");
        NpyStream::create(&empty, "<u4", 4, &[])
            .unwrap()
            .finish()
            .unwrap();
        let e = read_array(&empty).unwrap();
        assert_eq!(
            (e.scalar, e.shape, e.bytes.len()),
            (Scalar::U32, vec![0], 0)
        );
    }

    #[test]
    fn records_round_trip_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.npy");
        let t = [
            Transform64::translation([1.0, -2.0, 3.5]),
            Transform64::IDENTITY,
        ];
        write_records(&path, &t).unwrap();
        assert_eq!(read_records::<Transform64>(&path).unwrap(), t);
        let err = read_records::<Node>(&path).unwrap_err().to_string();
        assert!(err.contains("wrong dtype"), "{err}");
    }
}
