//! Point clouds of laser line scanners and scanning probes: ASCII XYZ and PLY (ASCII, binary little- and big-endian), streamed once, measured points only (the nominal is the nominal plane).
//!
//! The PLY reader is errmap's own: the PLY crates read the whole payload into a map per vertex
//! (ply-rs 0.1.3, last released 2020, and its fork ply-rs-bw) and report no byte offsets;
//! here only the vertex element's x, y, z are kept and a truncated file names the byte where
//! it ends. See `docs/probe-files.md`, "Point clouds".

use std::io::BufRead;
use std::path::Path;

use super::point::{check_plane, plane_nominal, point_row, Place, RawPoint, Row};
use super::ProbeSpec;
use errmap_core::error::{Error, Location, Result};

/// Read an XYZ file: per line `x y z` (blanks, tabs or commas between), more values ignored,
/// blank lines and `#` comments skipped.
pub(super) fn read_xyz(path: &Path, spec: &ProbeSpec) -> Result<Vec<Row>> {
    check_plane(path, 1, spec, "an XYZ point cloud has no nominal points")?;
    let reader = std::io::BufReader::with_capacity(1 << 16, errmap_core::io::open(path)?);
    let mut rows = Vec::new();
    for (i, bytes) in reader.split(b'\n').enumerate() {
        let line = i as u64 + 1;
        let bytes = bytes.map_err(|e| Error::read(path, e))?;
        let text = String::from_utf8_lossy(&bytes);
        let text = text.trim_start_matches('\u{feff}').trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = text
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|f| !f.is_empty())
            .collect();
        if fields.len() < 3 {
            return Err(Error::input(
                Location::line(path, line),
                format!("{} value(s); a point needs x y z", fields.len()),
                "write one point per line: x y z in mm (more values are ignored)",
            ));
        }
        let mut measured_mm = [0.0; 3];
        for k in 0..3 {
            measured_mm[k] = number(fields[k]).ok_or_else(|| {
                Error::input(
                    Location::cell(path, line, (k + 1).to_string()),
                    format!("'{}' is not a finite number", fields[k]),
                    "write x y z as decimal numbers in mm, such as 12.5",
                )
            })?;
        }
        let raw = RawPoint {
            id: None,
            line,
            measured_mm,
            nominal_mm: plane_nominal(measured_mm, spec),
            vector: None,
        };
        rows.push(point_row(raw, &Place::line(path, line), spec)?);
    }
    Ok(rows)
}

fn number(text: &str) -> Option<f64> {
    text.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// How the body of a PLY file is written.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The value of `bytes` (exactly [`Scalar::size`] of them).
    fn value(self, b: &[u8], enc: Encoding) -> f64 {
        let mut a = [0u8; 8];
        a[..b.len()].copy_from_slice(b);
        if enc == Encoding::Big {
            a[..b.len()].reverse();
        }
        match self {
            Scalar::I8 => f64::from(a[0] as i8),
            Scalar::U8 => f64::from(a[0]),
            Scalar::I16 => f64::from(i16::from_le_bytes([a[0], a[1]])),
            Scalar::U16 => f64::from(u16::from_le_bytes([a[0], a[1]])),
            Scalar::I32 => f64::from(i32::from_le_bytes([a[0], a[1], a[2], a[3]])),
            Scalar::U32 => f64::from(u32::from_le_bytes([a[0], a[1], a[2], a[3]])),
            Scalar::F32 => f64::from(f32::from_le_bytes([a[0], a[1], a[2], a[3]])),
            Scalar::F64 => f64::from_le_bytes(a),
        }
    }
}

/// A property of an element: a scalar, or a list (count type, item type).
#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: Scalar,
    list_count: Option<Scalar>,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
    /// Header line of the element, for messages.
    line: u64,
}

/// Read a PLY file's vertices as measured points.
pub(super) fn read_ply(path: &Path, spec: &ProbeSpec) -> Result<Vec<Row>> {
    check_plane(path, 1, spec, "a PLY point cloud has no nominal points")?;
    let mut reader = std::io::BufReader::with_capacity(1 << 16, errmap_core::io::open(path)?);
    let (encoding, elements, header_lines, header_bytes) = header(path, &mut reader)?;
    let Some(vi) = elements.iter().position(|e| e.name == "vertex") else {
        return Err(Error::input(
            Location::file(path),
            "the header declares no 'vertex' element",
            "a point cloud's points are the vertex element (element vertex N, property float x, y, z)",
        ));
    };
    let vertex = &elements[vi];
    let mut xyz = [0usize; 3];
    for (k, name) in ["x", "y", "z"].iter().enumerate() {
        xyz[k] = vertex
            .properties
            .iter()
            .position(|p| p.name == *name && p.list_count.is_none())
            .ok_or_else(|| {
                Error::input(
                    Location::line(path, vertex.line),
                    format!("the vertex element has no scalar property '{name}'"),
                    "the vertices need properties x, y and z (float or double, mm)",
                )
            })?;
    }
    let mut body = Body {
        path,
        reader,
        encoding,
        byte: header_bytes,
        line: header_lines,
        values: Vec::new(),
    };
    // Elements before the vertices are read past; those after are not read at all.
    for e in &elements[..vi] {
        for _ in 0..e.count {
            body.instance(e, None)?;
        }
    }
    let mut rows = Vec::new();
    for n in 0..vertex.count {
        let start = body.byte;
        let line = body.instance(vertex, Some((n, vertex.count)))?;
        let measured_mm = [
            body.values[xyz[0]],
            body.values[xyz[1]],
            body.values[xyz[2]],
        ];
        let (place, row_line) = if encoding == Encoding::Ascii {
            (Place::line(path, line), line)
        } else {
            let at = Location::file(path);
            let place = Place {
                row: at.clone(),
                normal: at.clone(),
                vector: at,
                prefix: format!("vertex {} (byte {start}): ", n + 1),
            };
            (place, n + 1)
        };
        if let Some(k) = (0..3).find(|&k| !measured_mm[k].is_finite()) {
            return Err(Error::input(
                place.row.clone(),
                format!(
                    "{}{} = {} is not a finite number",
                    place.prefix,
                    ["x", "y", "z"][k],
                    measured_mm[k]
                ),
                "NaN and infinity are not measurements; remove the vertex or export it again",
            ));
        }
        let raw = RawPoint {
            id: None,
            line: row_line,
            measured_mm,
            nominal_mm: plane_nominal(measured_mm, spec),
            vector: None,
        };
        rows.push(point_row(raw, &place, spec)?);
    }
    Ok(rows)
}

/// The header: encoding, elements, lines and bytes it takes.
fn header(path: &Path, reader: &mut impl BufRead) -> Result<(Encoding, Vec<Element>, u64, u64)> {
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut bytes = 0u64;
    let mut line_no = 0u64;
    let mut buf = Vec::new();
    loop {
        buf.clear();
        let n = reader
            .read_until(b'\n', &mut buf)
            .map_err(|e| Error::read(path, e))?;
        if n == 0 {
            return Err(Error::input(
                Location::line(path, line_no),
                "the PLY header has no end_header line",
                "the file is cut short or is not a PLY file",
            ));
        }
        bytes += n as u64;
        line_no += 1;
        let text = String::from_utf8_lossy(&buf);
        let words: Vec<&str> = text.split_whitespace().collect();
        let bad = |message: String, hint: &str| {
            Error::input(Location::line(path, line_no), message, hint)
        };
        if line_no == 1 {
            if words != ["ply"] {
                return Err(bad(
                    "a PLY file starts with the line 'ply'".into(),
                    "is this a PLY file? (.ply files are read as PLY)",
                ));
            }
            continue;
        }
        match words.first().copied() {
            Some("format") => {
                encoding = Some(match words.get(1).copied() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::Little,
                    Some("binary_big_endian") => Encoding::Big,
                    other => {
                        return Err(bad(
                            format!("unknown PLY format '{}'", other.unwrap_or("")),
                            "the format is ascii, binary_little_endian or binary_big_endian",
                        ))
                    }
                })
            }
            Some("comment" | "obj_info") | None => {}
            Some("element") => {
                let count = words.get(2).and_then(|c| c.parse::<u64>().ok());
                match (words.get(1), count) {
                    (Some(name), Some(count)) => elements.push(Element {
                        name: name.to_string(),
                        count,
                        properties: Vec::new(),
                        line: line_no,
                    }),
                    _ => {
                        return Err(bad(
                            format!("'{}' is not 'element NAME COUNT'", text.trim()),
                            "write e.g. element vertex 1000",
                        ))
                    }
                }
            }
            Some("property") => {
                let property = match words.get(1).copied() {
                    Some("list") => match (
                        words.get(2).and_then(|t| Scalar::parse(t)),
                        words.get(3).and_then(|t| Scalar::parse(t)),
                        words.get(4),
                    ) {
                        (Some(count), Some(kind), Some(name)) => Property {
                            name: name.to_string(),
                            kind,
                            list_count: Some(count),
                        },
                        _ => {
                            return Err(bad(
                                format!(
                                    "'{}' is not 'property list COUNT_TYPE TYPE NAME'",
                                    text.trim()
                                ),
                                "PLY types: char uchar short ushort int uint float double",
                            ))
                        }
                    },
                    t => match (t.and_then(Scalar::parse), words.get(2)) {
                        (Some(kind), Some(name)) => Property {
                            name: name.to_string(),
                            kind,
                            list_count: None,
                        },
                        _ => {
                            return Err(bad(
                                format!("'{}' is not 'property TYPE NAME'", text.trim()),
                                "PLY types: char uchar short ushort int uint float double",
                            ))
                        }
                    },
                };
                match elements.last_mut() {
                    Some(e) => e.properties.push(property),
                    None => {
                        return Err(bad(
                            "a property before any element".into(),
                            "declare 'element NAME COUNT' before its properties",
                        ))
                    }
                }
            }
            Some("end_header") => break,
            Some(other) => return Err(bad(
                format!("'{other}' is not a PLY header keyword"),
                "the header has format, comment, obj_info, element, property and end_header lines",
            )),
        }
    }
    let encoding = encoding.ok_or_else(|| {
        Error::input(
            Location::line(path, line_no),
            "the PLY header has no format line",
            "add 'format ascii 1.0' or 'format binary_little_endian 1.0' after 'ply'",
        )
    })?;
    Ok((encoding, elements, line_no, bytes))
}

/// The body of a PLY file being read: where the reader is (byte, and line for ASCII).
struct Body<'a, R> {
    path: &'a Path,
    reader: R,
    encoding: Encoding,
    byte: u64,
    line: u64,
    /// The scalar values of the last instance read (a list's items are not kept).
    values: Vec<f64>,
}

impl<R: BufRead> Body<'_, R> {
    /// Read one instance of `e` into `values`; `vertex` is (index, count) for messages. The
    /// instance's line (ASCII) or 0.
    fn instance(&mut self, e: &Element, vertex: Option<(u64, u64)>) -> Result<u64> {
        self.values.clear();
        let what = match vertex {
            Some((n, count)) => format!("vertex {} of {count}", n + 1),
            None => format!("an element '{}'", e.name),
        };
        if self.encoding == Encoding::Ascii {
            return self.ascii_instance(e, &what);
        }
        let start = self.byte;
        for p in &e.properties {
            match p.list_count {
                None => {
                    let v = self.scalar(p.kind, start, &what)?;
                    self.values.push(v);
                }
                Some(count_type) => {
                    let count = self.scalar(count_type, start, &what)?;
                    if !(0.0..=1e6).contains(&count) {
                        return Err(
                            self.binary_error(start, format!("{what}: a list of {count} items"))
                        );
                    }
                    for _ in 0..count as u64 {
                        self.scalar(p.kind, start, &what)?;
                    }
                    self.values.push(f64::NAN);
                }
            }
        }
        Ok(0)
    }

    fn scalar(&mut self, kind: Scalar, start: u64, what: &str) -> Result<f64> {
        let mut b = [0u8; 8];
        let size = kind.size();
        let mut got = 0;
        while got < size {
            let n = self
                .reader
                .read(&mut b[got..size])
                .map_err(|e| Error::read(self.path, e))?;
            if n == 0 {
                let at = self.byte + got as u64;
                return Err(Error::input(
                    Location::file(self.path),
                    format!(
                        "at byte {at}: the file ends inside {what} (which starts at byte {start})"
                    ),
                    "the PLY file is truncated: export it again, or correct the element count in its header",
                ));
            }
            got += n;
        }
        self.byte += size as u64;
        Ok(kind.value(&b[..size], self.encoding))
    }

    fn binary_error(&self, start: u64, message: String) -> Error {
        Error::input(
            Location::file(self.path),
            format!("at byte {start}: {message}"),
            "the file is damaged or its header does not describe it; export it again",
        )
    }

    /// One ASCII line: the element's values, lists read past.
    fn ascii_instance(&mut self, e: &Element, what: &str) -> Result<u64> {
        let mut buf = Vec::new();
        let text = loop {
            buf.clear();
            let n = self
                .reader
                .read_until(b'\n', &mut buf)
                .map_err(|err| Error::read(self.path, err))?;
            if n == 0 {
                return Err(Error::input(
                    Location::line(self.path, self.line),
                    format!("the file ends before {what}"),
                    "the PLY file is truncated: export it again, or correct the element count in its header",
                ));
            }
            self.byte += n as u64;
            self.line += 1;
            let text = String::from_utf8_lossy(&buf).trim().to_string();
            if !text.is_empty() {
                break text;
            }
        };
        let line = self.line;
        let mut words = text.split_whitespace();
        let mut next = |name: &str| -> Result<f64> {
            let word = words.next().ok_or_else(|| {
                Error::input(
                    Location::line(self.path, line),
                    format!("{what} has no value for '{name}'"),
                    "give one value per property of the header, in its order",
                )
            })?;
            word.parse::<f64>().map_err(|_| {
                Error::input(
                    Location::cell(self.path, line, name.to_string()),
                    format!("'{word}' is not a number"),
                    "write decimal numbers such as 12.5",
                )
            })
        };
        let mut values = Vec::with_capacity(e.properties.len());
        for p in &e.properties {
            match p.list_count {
                None => values.push(next(&p.name)?),
                Some(_) => {
                    let count = next(&p.name)?;
                    for _ in 0..(count.max(0.0) as u64) {
                        next(&p.name)?;
                    }
                    values.push(f64::NAN);
                }
            }
        }
        self.values = values;
        Ok(line)
    }
}
