//! Parquet tables through arrow: writing whole files atomically, reading columns back.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use arrow_array::builder::{ListBuilder, PrimitiveBuilder, StringBuilder};
use arrow_array::types::{ArrowPrimitiveType, Float64Type, Int64Type};
use arrow_array::{
    Array, ArrayRef, BooleanArray, FixedSizeListArray, Float32Array, Float64Array, Int64Array,
    ListArray, RecordBatch, StringArray, UInt64Array,
};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::WriterProperties;

use crate::DatasetError;

/// One column's values over the frames of an episode (or over episodes).
#[derive(Debug, Clone, PartialEq)]
pub enum Column {
    /// float32, `dim` per row (row-major); a vector feature, or a scalar when `dim == 1`.
    F32 {
        /// Values per row.
        dim: usize,
        /// The values.
        values: Vec<f32>,
    },
    /// int64 scalars.
    I64(Vec<i64>),
    /// bool scalars.
    Bool(Vec<bool>),
}

impl Column {
    /// Rows.
    pub fn rows(&self) -> usize {
        match self {
            Column::F32 { dim, values } => values.len() / (*dim).max(1),
            Column::I64(v) => v.len(),
            Column::Bool(v) => v.len(),
        }
    }

    /// Values per row.
    pub fn dim(&self) -> usize {
        match self {
            Column::F32 { dim, .. } => *dim,
            _ => 1,
        }
    }

    /// The numpy dtype name of its values.
    pub fn dtype(&self) -> &'static str {
        match self {
            Column::F32 { .. } => "float32",
            Column::I64(_) => "int64",
            Column::Bool(_) => "bool",
        }
    }

    /// The values as f64, row-major (statistics).
    pub fn as_f64(&self) -> Vec<f64> {
        match self {
            Column::F32 { values, .. } => values.iter().map(|&v| f64::from(v)).collect(),
            Column::I64(v) => v.iter().map(|&v| v as f64).collect(),
            Column::Bool(v) => v.iter().map(|&v| f64::from(u8::from(v))).collect(),
        }
    }

    /// The arrow field and array (`fixed_size_list<element: float>[dim]` for vectors, a plain
    /// column for scalars, as LeRobot stores them).
    pub fn to_arrow(&self, name: &str) -> (Field, ArrayRef) {
        match self {
            Column::F32 { dim, values } if *dim > 1 => {
                let item = Arc::new(Field::new("element", DataType::Float32, true));
                let values = Arc::new(Float32Array::from(values.clone()));
                let list = FixedSizeListArray::new(item.clone(), *dim as i32, values, None);
                let field = Field::new(name, DataType::FixedSizeList(item, *dim as i32), true);
                (field, Arc::new(list))
            }
            Column::F32 { values, .. } => (
                Field::new(name, DataType::Float32, true),
                Arc::new(Float32Array::from(values.clone())),
            ),
            Column::I64(v) => (
                Field::new(name, DataType::Int64, true),
                Arc::new(Int64Array::from(v.clone())),
            ),
            Column::Bool(v) => (
                Field::new(name, DataType::Boolean, true),
                Arc::new(BooleanArray::from(v.clone())),
            ),
        }
    }

    /// A column read back from an arrow array (the kinds `to_arrow` writes).
    pub fn from_arrow(array: &dyn Array) -> Option<Column> {
        let any = array.as_any();
        if let Some(a) = any.downcast_ref::<Float32Array>() {
            return Some(Column::F32 {
                dim: 1,
                values: a.values().to_vec(),
            });
        }
        if let Some(a) = any.downcast_ref::<Int64Array>() {
            return Some(Column::I64(a.values().to_vec()));
        }
        if let Some(a) = any.downcast_ref::<BooleanArray>() {
            return Some(Column::Bool((0..a.len()).map(|i| a.value(i)).collect()));
        }
        let a = any.downcast_ref::<FixedSizeListArray>()?;
        let values = a.values().as_any().downcast_ref::<Float32Array>()?;
        let dim = a.value_length() as usize;
        let start = a.offset() * dim;
        Some(Column::F32 {
            dim,
            values: values.values()[start..start + a.len() * dim].to_vec(),
        })
    }
}

/// A list column of one list of primitive values per row.
fn list_of<T: ArrowPrimitiveType>(name: &str, rows: &[Vec<T::Native>]) -> (Field, ArrayRef) {
    let mut b = ListBuilder::new(PrimitiveBuilder::<T>::new());
    for r in rows {
        b.values().append_slice(r);
        b.append(true);
    }
    let a = b.finish();
    (Field::new(name, a.data_type().clone(), true), Arc::new(a))
}

/// A `list<double>` column of one list per row.
pub fn list_f64(name: &str, rows: &[Vec<f64>]) -> (Field, ArrayRef) {
    list_of::<Float64Type>(name, rows)
}

/// A `list<int64>` column of one list per row.
pub fn list_i64(name: &str, rows: &[Vec<i64>]) -> (Field, ArrayRef) {
    list_of::<Int64Type>(name, rows)
}

/// A `list<string>` column of one list per row.
pub fn list_str(name: &str, rows: &[Vec<String>]) -> (Field, ArrayRef) {
    let mut b = ListBuilder::new(StringBuilder::new());
    for r in rows {
        for s in r {
            b.values().append_value(s);
        }
        b.append(true);
    }
    let a = b.finish();
    (Field::new(name, a.data_type().clone(), true), Arc::new(a))
}

/// A string column.
pub fn strings(name: &str, rows: &[String]) -> (Field, ArrayRef) {
    (
        Field::new(name, DataType::Utf8, true),
        Arc::new(StringArray::from(rows.to_vec())),
    )
}

/// A float64 column.
pub fn f64s(name: &str, rows: &[f64]) -> (Field, ArrayRef) {
    (
        Field::new(name, DataType::Float64, true),
        Arc::new(Float64Array::from(rows.to_vec())),
    )
}

/// A uint64 column.
pub fn u64s(name: &str, rows: &[u64]) -> (Field, ArrayRef) {
    (
        Field::new(name, DataType::UInt64, true),
        Arc::new(UInt64Array::from(rows.to_vec())),
    )
}

/// A nullable bool column.
pub fn opt_bools(name: &str, rows: &[Option<bool>]) -> (Field, ArrayRef) {
    (
        Field::new(name, DataType::Boolean, true),
        Arc::new(BooleanArray::from(rows.to_vec())),
    )
}

/// Writes the columns as one parquet file (snappy), atomically: a reader or a killed writer
/// sees the old file or the whole new one.
pub fn write(
    path: &Path,
    columns: Vec<(Field, ArrayRef)>,
    metadata: HashMap<String, String>,
) -> Result<(), DatasetError> {
    let (fields, arrays): (Vec<Field>, Vec<ArrayRef>) = columns.into_iter().unzip();
    let schema = Arc::new(Schema::new_with_metadata(fields, metadata));
    let err = |e: &dyn std::fmt::Display| DatasetError::new(format!("{}: {e}", path.display()));
    let batch = RecordBatch::try_new(schema.clone(), arrays).map_err(|e| err(&e))?;
    let props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .build();
    let mut bytes = Vec::new();
    let mut w = ArrowWriter::try_new(&mut bytes, schema, Some(props)).map_err(|e| err(&e))?;
    w.write(&batch).map_err(|e| err(&e))?;
    w.close().map_err(|e| err(&e))?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| DatasetError::io(dir, e))?;
    }
    modesuite_engine::fsio::write_atomic(path, &bytes).map_err(|e| err(&e))
}

/// Every record batch of a parquet file.
pub fn read(path: &Path) -> Result<Vec<RecordBatch>, DatasetError> {
    let file = std::fs::File::open(path).map_err(|e| DatasetError::io(path, e))?;
    let err = |e: &dyn std::fmt::Display| DatasetError::new(format!("{}: {e}", path.display()));
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| err(&e))?
        .build()
        .map_err(|e| err(&e))?;
    reader.map(|b| b.map_err(|e| err(&e))).collect()
}

/// The named column of `batch`, or a located error.
pub fn column<'a>(
    batch: &'a RecordBatch,
    name: &str,
    path: &Path,
) -> Result<&'a ArrayRef, DatasetError> {
    batch
        .column_by_name(name)
        .ok_or_else(|| DatasetError::new(format!("{}: no column {name:?}", path.display())))
}

/// A column's values as `T`'s array, or a located error naming the expected type.
pub fn typed<'a, T: 'static>(
    array: &'a ArrayRef,
    name: &str,
    what: &str,
    path: &Path,
) -> Result<&'a T, DatasetError> {
    array.as_any().downcast_ref::<T>().ok_or_else(|| {
        DatasetError::new(format!(
            "{}: column {name:?} is {}, expected {what}",
            path.display(),
            array.data_type()
        ))
    })
}

/// The named column of `batch` as `T`'s array, or a located error (missing, or of another
/// type than `what`).
pub fn get<'a, T: 'static>(
    batch: &'a RecordBatch,
    name: &str,
    what: &str,
    path: &Path,
) -> Result<&'a T, DatasetError> {
    typed::<T>(column(batch, name, path)?, name, what, path)
}

/// Row `i` of a `list<double>` (or `list<int64>`) column as f64 values.
pub fn list_row_f64(a: &ListArray, i: usize) -> Option<Vec<f64>> {
    let v = a.value(i);
    if let Some(f) = v.as_any().downcast_ref::<Float64Array>() {
        return Some(f.values().to_vec());
    }
    v.as_any()
        .downcast_ref::<Int64Array>()
        .map(|x| x.values().iter().map(|&x| x as f64).collect())
}

/// Row `i` of a `list<string>` column.
pub fn list_row_str(a: &ListArray, i: usize) -> Option<Vec<String>> {
    let v = a.value(i);
    let s = v.as_any().downcast_ref::<StringArray>()?;
    Some((0..s.len()).map(|k| s.value(k).to_string()).collect())
}
