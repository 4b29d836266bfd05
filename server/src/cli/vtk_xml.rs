//! The XML `.vtu` reader of `isoray push`: unstructured grids as VTK, ParaView, meshio and
//! pyvista write them, by default and on request.
//!
//! How it works: the file is memory-mapped (filebuffer) and read once. quick-xml walks the
//! XML part as events over the mapped bytes and stops at `<AppendedData>` (what follows is
//! binary, not XML); each `<DataArray>` is noted with its type, components, format and where
//! its bytes are, and only the arrays the push needs are decoded: the points, the three cell
//! arrays and one scalar array. An array is `ascii` text, inline `binary` (base64), or
//! `appended` at an offset into the raw or base64 appended section. Binary data starts with a
//! header of `UInt32` or `UInt64` integers (`header_type`): one byte count, or, with a
//! `compressor`, the block count, the block size, the last block's size and each block's
//! compressed size; blocks (zlib, LZ4 or xz, VTK's `vtkZLibDataCompressor`,
//! `vtkLZ4DataCompressor`, `vtkLZMADataCompressor`) are inflated in parallel, each checked
//! against the size the header promises, and the total against the size the array must have.
//! Base64 text is decoded segment by segment (a segment ends at padding), because writers
//! encode the header and the data apart.
//!
//! We read XML here rather than with vtkio 0.6.3, which refused every zlib array of more
//! than one 32 KiB block (`DataArraySizeMismatch`: what VTK, ParaView and meshio write by
//! default) and has no LZ4 or xz; its 0.7 release candidate cannot read raw appended data.

use super::vtk_grid::{pick_array, Grid, Picked};
use base64::Engine;
use filebuffer::FileBuffer;
use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use rayon::prelude::*;
use std::borrow::Cow;
use std::ops::Range;
use std::path::Path;

/// A VTK numeric type.
#[derive(Clone, Copy, Debug, PartialEq)]
enum NumType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl NumType {
    fn parse(s: &str) -> Option<NumType> {
        Some(match s {
            "Int8" | "Char" => NumType::I8,
            "UInt8" | "UChar" => NumType::U8,
            "Int16" => NumType::I16,
            "UInt16" => NumType::U16,
            "Int32" => NumType::I32,
            "UInt32" => NumType::U32,
            "Int64" => NumType::I64,
            "UInt64" => NumType::U64,
            "Float32" => NumType::F32,
            "Float64" => NumType::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            NumType::I8 | NumType::U8 => 1,
            NumType::I16 | NumType::U16 => 2,
            NumType::I32 | NumType::U32 | NumType::F32 => 4,
            NumType::I64 | NumType::U64 | NumType::F64 => 8,
        }
    }
}

/// VTK's block compressors.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Compressor {
    Zlib,
    Lz4,
    Lzma,
}

/// Where a section of the piece is: which XML element holds an array.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Section {
    Points,
    Cells,
    PointData,
    CellData,
    Other,
}

/// Where an array's bytes are.
#[derive(Clone, Debug)]
enum Source {
    Ascii(Range<usize>),
    Base64(Range<usize>),
    Appended(usize),
}

#[derive(Clone, Debug)]
struct ArrayDesc {
    section: Section,
    name: String,
    ty: NumType,
    components: usize,
    source: Source,
}

#[derive(Debug, Default)]
struct Piece {
    points: usize,
    cells: usize,
    arrays: Vec<ArrayDesc>,
}

/// The appended section: where its data starts (after `_`) and ends, and its encoding.
#[derive(Debug)]
struct Appended {
    data: Range<usize>,
    base64: bool,
}

/// A mapped `.vtu` and what its XML says.
struct VtuFile {
    map: FileBuffer,
    meta: Meta,
}

/// What a `.vtu`'s XML says.
#[derive(Debug, Default)]
struct Meta {
    big_endian: bool,
    header_u64: bool,
    compressor: Option<Compressor>,
    pieces: Vec<Piece>,
    appended: Option<Appended>,
}

fn attr(e: &BytesStart<'_>, name: &str) -> Result<Option<String>, String> {
    match e.try_get_attribute(name) {
        Ok(Some(a)) => a
            .unescape_value()
            .map(|v| Some(v.into_owned()))
            .map_err(|err| format!("attribute {name}: {err}")),
        Ok(None) => Ok(None),
        Err(err) => Err(format!("attribute {name}: {err}")),
    }
}

fn count_attr(e: &BytesStart<'_>, name: &str) -> Result<usize, String> {
    let v = attr(e, name)?.ok_or_else(|| format!("<Piece> has no {name}"))?;
    v.trim()
        .parse()
        .map_err(|_| format!("<Piece {name}=\"{v}\"> is not a count"))
}

fn position<R>(reader: &Reader<R>) -> usize {
    usize::try_from(reader.buffer_position()).unwrap_or(usize::MAX)
}

impl VtuFile {
    /// Maps `path` and reads its XML up to the appended data.
    fn open(path: &Path) -> Result<VtuFile, String> {
        let map = FileBuffer::open(path).map_err(|e| e.to_string())?;
        let mut meta = Meta::default();
        meta.parse(&map)?;
        Ok(VtuFile { map, meta })
    }
}

impl Meta {
    fn parse(&mut self, bytes: &[u8]) -> Result<(), String> {
        let mut reader = Reader::from_reader(bytes);
        let mut section = Section::Other;
        let mut pending: Option<ArrayDesc> = None;
        // Elements inside the pending <DataArray> (VTK writes <InformationKey>s there).
        let mut nested = 0usize;
        let mut seen_root = false;
        let mut appended = None;
        loop {
            let before = position(&reader);
            let event = reader
                .read_event()
                .map_err(|e| format!("XML error at byte {before}: {e}"))?;
            match event {
                Event::Start(_) if pending.is_some() => nested += 1,
                Event::End(e) if pending.is_some() && e.name().as_ref() != b"DataArray" => {
                    nested = nested.saturating_sub(1);
                }
                Event::Start(e) | Event::Empty(e) => {
                    let empty = reader_was_empty(bytes, position(&reader));
                    let name = e.name();
                    match name.as_ref() {
                        b"VTKFile" => {
                            seen_root = true;
                            self.root(&e)?;
                        }
                        b"Piece" => {
                            self.pieces.push(Piece {
                                points: count_attr(&e, "NumberOfPoints")?,
                                cells: count_attr(&e, "NumberOfCells")?,
                                arrays: Vec::new(),
                            });
                        }
                        b"Points" => section = Section::Points,
                        b"Cells" => section = Section::Cells,
                        b"PointData" => section = Section::PointData,
                        b"CellData" => section = Section::CellData,
                        b"DataArray" => {
                            let desc = data_array(&e, section)?;
                            if empty || matches!(desc.source, Source::Appended(_)) {
                                self.push_array(desc)?;
                            } else {
                                pending = Some(desc);
                            }
                        }
                        b"AppendedData" => {
                            let encoding =
                                attr(&e, "encoding")?.unwrap_or_else(|| "raw".to_string());
                            let base64 = match encoding.as_str() {
                                "raw" => false,
                                "base64" => true,
                                other => {
                                    return Err(format!(
                                        "<AppendedData encoding=\"{other}\">: only raw and base64"
                                    ))
                                }
                            };
                            let after = position(&reader);
                            appended = Some(appended_section(bytes, after, base64)?);
                            break;
                        }
                        _ => {}
                    }
                }
                Event::Text(t) if nested == 0 && !t.iter().all(u8::is_ascii_whitespace) => {
                    if let Some(desc) = &mut pending {
                        let end = position(&reader);
                        match &mut desc.source {
                            Source::Ascii(r) | Source::Base64(r) => {
                                if r.start == r.end {
                                    *r = before..end;
                                } else {
                                    r.end = end;
                                }
                            }
                            Source::Appended(_) => {}
                        }
                    }
                }
                Event::End(e) => match e.name().as_ref() {
                    b"DataArray" => {
                        if let Some(desc) = pending.take() {
                            self.push_array(desc)?;
                        }
                    }
                    b"Points" | b"Cells" | b"PointData" | b"CellData" => section = Section::Other,
                    _ => {}
                },
                Event::Eof => break,
                _ => {}
            }
        }
        if !seen_root {
            return Err("not a VTK XML file (no <VTKFile>)".into());
        }
        if self.pieces.is_empty() {
            return Err("no <Piece> in the file".into());
        }
        self.appended = appended;
        Ok(())
    }

    fn root(&mut self, e: &BytesStart<'_>) -> Result<(), String> {
        match attr(e, "type")?.as_deref() {
            Some("UnstructuredGrid") => {}
            Some(other) => {
                return Err(format!(
                    "a {other} file; only unstructured grids (.vtu) can be pushed"
                ))
            }
            None => return Err("<VTKFile> has no type".into()),
        }
        self.big_endian = match attr(e, "byte_order")?.as_deref() {
            None | Some("LittleEndian") => false,
            Some("BigEndian") => true,
            Some(other) => return Err(format!("byte_order \"{other}\"")),
        };
        self.header_u64 = match attr(e, "header_type")?.as_deref() {
            None | Some("UInt32") => false,
            Some("UInt64") => true,
            Some(other) => return Err(format!("header_type \"{other}\": UInt32 or UInt64")),
        };
        self.compressor = match attr(e, "compressor")?.as_deref() {
            None | Some("") => None,
            Some("vtkZLibDataCompressor") => Some(Compressor::Zlib),
            Some("vtkLZ4DataCompressor") => Some(Compressor::Lz4),
            Some("vtkLZMADataCompressor") => Some(Compressor::Lzma),
            Some(other) => return Err(format!("compressor \"{other}\" is not one VTK writes")),
        };
        Ok(())
    }

    fn push_array(&mut self, desc: ArrayDesc) -> Result<(), String> {
        let piece = self
            .pieces
            .last_mut()
            .ok_or_else(|| format!("<DataArray Name=\"{}\"> outside a <Piece>", desc.name))?;
        piece.arrays.push(desc);
        Ok(())
    }
}

impl VtuFile {
    /// The decoded bytes of a binary array of `want` bytes.
    fn binary(&self, desc: &ArrayDesc, want: usize) -> Result<Vec<u8>, String> {
        let bytes: &[u8] = &self.map;
        match &desc.source {
            Source::Ascii(_) => Err("an ascii array has no bytes".into()),
            Source::Base64(range) => {
                let decoded = base64_segments(&bytes[range.clone()])?;
                Ok(self.blocks(&decoded, want)?.into_owned())
            }
            Source::Appended(offset) => {
                let app = self.meta.appended.as_ref().ok_or(
                    "the array is appended (format=\"appended\") but the file has no <AppendedData>",
                )?;
                let start = app
                    .data
                    .start
                    .checked_add(*offset)
                    .filter(|&s| s <= app.data.end);
                let start = start.ok_or_else(|| {
                    format!("offset {offset} is past the end of the appended data")
                })?;
                if app.base64 {
                    // Each array is its own base64 text, up to the next array's offset.
                    let end = self
                        .meta
                        .pieces
                        .iter()
                        .flat_map(|p| &p.arrays)
                        .filter_map(|a| match a.source {
                            Source::Appended(o) => Some(app.data.start.saturating_add(o)),
                            Source::Ascii(_) | Source::Base64(_) => None,
                        })
                        .filter(|&s| s > start)
                        .min()
                        .unwrap_or(app.data.end)
                        .min(app.data.end);
                    let decoded = base64_segments(&bytes[start..end])?;
                    Ok(self.blocks(&decoded, want)?.into_owned())
                } else {
                    Ok(self.blocks(&bytes[start..app.data.end], want)?.into_owned())
                }
            }
        }
    }

    /// The array's data from binary `data` (header, then data or compressed blocks), which
    /// must come to `want` bytes.
    fn blocks<'a>(&self, data: &'a [u8], want: usize) -> Result<Cow<'a, [u8]>, String> {
        let word = if self.meta.header_u64 { 8 } else { 4 };
        let uint = |i: usize| -> Result<usize, String> {
            let b = data
                .get(i * word..(i + 1) * word)
                .ok_or("the data ends inside its header")?;
            let v = if self.meta.header_u64 {
                let a: [u8; 8] = b.try_into().map_err(|_| "header word")?;
                if self.meta.big_endian {
                    u64::from_be_bytes(a)
                } else {
                    u64::from_le_bytes(a)
                }
            } else {
                let a: [u8; 4] = b.try_into().map_err(|_| "header word")?;
                u64::from(if self.meta.big_endian {
                    u32::from_be_bytes(a)
                } else {
                    u32::from_le_bytes(a)
                })
            };
            usize::try_from(v).map_err(|_| format!("header value {v} is too large"))
        };
        let Some(compressor) = self.meta.compressor else {
            let n = uint(0)?;
            if n != want {
                return Err(format!("the header says {n} bytes, the array needs {want}"));
            }
            return data
                .get(word..word + n)
                .map(Cow::Borrowed)
                .ok_or_else(|| format!("{n} bytes promised, {} there", data.len() - word));
        };
        let blocks = uint(0)?;
        let block_size = uint(1)?;
        let last = uint(2)?;
        let header_words = blocks
            .checked_add(3)
            .filter(|&w| w.saturating_mul(word) <= data.len())
            .ok_or_else(|| format!("a header of {blocks} blocks is longer than the data"))?;
        let sizes: Vec<usize> = (3..header_words).map(uint).collect::<Result<_, _>>()?;
        let raw_size = |i: usize| {
            if i + 1 == blocks && last != 0 {
                last
            } else {
                block_size
            }
        };
        let total = (0..blocks)
            .map(raw_size)
            .fold(0usize, usize::saturating_add);
        if total != want {
            return Err(format!(
                "the header's {blocks} blocks hold {total} bytes, the array needs {want}"
            ));
        }
        let mut inputs = Vec::with_capacity(blocks);
        let mut at = header_words * word;
        for (i, &size) in sizes.iter().enumerate() {
            let end = at.checked_add(size).filter(|&e| e <= data.len());
            let end = end.ok_or_else(|| format!("compressed block {i} runs past the data"))?;
            inputs.push((i, &data[at..end], raw_size(i)));
            at = end;
        }
        let parts: Vec<Vec<u8>> = inputs
            .par_iter()
            .map(|&(i, input, size)| {
                inflate(compressor, input, size).map_err(|e| format!("block {i}: {e}"))
            })
            .collect::<Result<_, _>>()?;
        Ok(Cow::Owned(parts.concat()))
    }

    /// `count` values of the array as f64.
    fn values(&self, desc: &ArrayDesc, count: usize) -> Result<Vec<f64>, String> {
        let what = |e: String| format!("<DataArray Name=\"{}\">: {e}", desc.name);
        if let Source::Ascii(range) = &desc.source {
            let text = std::str::from_utf8(&self.map[range.clone()])
                .map_err(|_| what("ascii data is not text".into()))?;
            let values: Vec<f64> = text
                .split_ascii_whitespace()
                .map(|t| {
                    t.parse::<f64>()
                        .map_err(|_| what(format!("{t:?} is not a number")))
                })
                .collect::<Result<_, _>>()?;
            if values.len() != count {
                return Err(what(format!("{} values, {count} expected", values.len())));
            }
            return Ok(values);
        }
        let want = count
            .checked_mul(desc.ty.size())
            .ok_or_else(|| what("too large".into()))?;
        let bytes = self.binary(desc, want).map_err(what)?;
        Ok(to_f64(&bytes, desc.ty, self.meta.big_endian))
    }
}

/// The appended section from `after` (just past `<AppendedData ...>`): data after the
/// `_` marker, up to `</AppendedData>`.
fn appended_section(bytes: &[u8], after: usize, base64: bool) -> Result<Appended, String> {
    let rest = bytes.get(after..).unwrap_or_default();
    let underscore = rest
        .iter()
        .position(|&b| b == b'_')
        .ok_or("<AppendedData> has no '_' before its data")?;
    let start = after + underscore + 1;
    let close = b"</AppendedData>";
    let end = bytes
        .windows(close.len())
        .rposition(|w| w == close)
        .filter(|&end| end >= start)
        .unwrap_or(bytes.len());
    Ok(Appended {
        data: start..end,
        base64,
    })
}

/// Whether the tag that ends just before `end` is empty (`<... />`).
fn reader_was_empty(bytes: &[u8], end: usize) -> bool {
    end >= 2 && bytes.get(end - 2) == Some(&b'/')
}

/// A `<DataArray>`'s description; inline data gets its range from the text that follows.
fn data_array(e: &BytesStart<'_>, section: Section) -> Result<ArrayDesc, String> {
    let name = attr(e, "Name")?.unwrap_or_default();
    let what = |msg: String| format!("<DataArray Name=\"{name}\">: {msg}");
    let ty_name = attr(e, "type")?.ok_or_else(|| what("no type".into()))?;
    let ty = NumType::parse(&ty_name).ok_or_else(|| what(format!("type \"{ty_name}\"")))?;
    let components = match attr(e, "NumberOfComponents")? {
        Some(c) => c
            .trim()
            .parse::<usize>()
            .ok()
            .filter(|&c| c > 0)
            .ok_or_else(|| what(format!("NumberOfComponents=\"{c}\"")))?,
        None => 1,
    };
    let format = attr(e, "format")?.unwrap_or_else(|| "ascii".into());
    let source = match format.as_str() {
        "ascii" => Source::Ascii(0..0),
        "binary" => Source::Base64(0..0),
        "appended" => {
            let offset =
                attr(e, "offset")?.ok_or_else(|| what("appended without offset".into()))?;
            Source::Appended(
                offset
                    .trim()
                    .parse()
                    .map_err(|_| what(format!("offset=\"{offset}\"")))?,
            )
        }
        other => return Err(what(format!("format=\"{other}\""))),
    };
    Ok(ArrayDesc {
        section,
        name,
        ty,
        components,
        source,
    })
}

/// Inflates one block to exactly `size` bytes. `size` comes from the file's block header,
/// so nothing is reserved up front beyond what the input could give (a 2 KiB `.vtu`
/// declaring one zlib block of 12 GB had the reader ask for 12 GB at once): zlib and xz
/// output grows with what the stream actually yields and stops one byte past `size`, and an
/// LZ4 block, which cannot expand more than 255 times (a match's length grows by at most
/// 255 a byte), is refused when it declares more than that before its buffer is made.
fn inflate(compressor: Compressor, input: &[u8], size: usize) -> Result<Vec<u8>, String> {
    use std::io::Read;
    /// What the first reservation may be: the rest comes as the data does.
    const RESERVE: usize = 1 << 20;
    let out = match compressor {
        Compressor::Zlib => {
            let mut out = Vec::with_capacity(size.min(RESERVE));
            flate2::read::ZlibDecoder::new(input)
                .take(size as u64 + 1)
                .read_to_end(&mut out)
                .map_err(|e| format!("zlib: {e}"))?;
            out
        }
        Compressor::Lz4 => {
            let most = input.len().saturating_mul(255).saturating_add(16);
            if size > most {
                return Err(format!(
                    "the header says {size} bytes, more than LZ4's {} compressed bytes can hold",
                    input.len()
                ));
            }
            let mut out = vec![0u8; size];
            let n = lz4_flex::block::decompress_into(input, &mut out)
                .map_err(|e| format!("lz4: {e}"))?;
            out.truncate(n);
            out
        }
        Compressor::Lzma => {
            let mut out = Capped {
                bytes: Vec::with_capacity(size.min(RESERVE)),
                cap: size.saturating_add(1),
            };
            lzma_rs::xz_decompress(&mut std::io::BufReader::new(input), &mut out)
                .map_err(|e| format!("xz: {e}"))?;
            out.bytes
        }
    };
    if out.len() != size {
        return Err(format!(
            "inflates to {} bytes, the header says {size}",
            out.len()
        ));
    }
    Ok(out)
}

/// A writer that takes at most `cap` bytes, then fails: an xz block inflates no further than
/// one byte past what its header declares.
struct Capped {
    bytes: Vec<u8>,
    cap: usize,
}

impl std::io::Write for Capped {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let room = self.cap - self.bytes.len();
        if room == 0 && !buf.is_empty() {
            return Err(std::io::Error::other(
                "more bytes than the block's header declares",
            ));
        }
        let n = buf.len().min(room);
        self.bytes.extend_from_slice(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Decodes base64 text made of one or more padded segments (VTK and meshio encode a binary
/// array's header and its data apart), ignoring whitespace.
fn base64_segments(text: &[u8]) -> Result<Vec<u8>, String> {
    let clean: Vec<u8> = text
        .iter()
        .copied()
        .filter(|c| !c.is_ascii_whitespace())
        .collect();
    let engine = base64::engine::general_purpose::STANDARD;
    let mut out = Vec::with_capacity(clean.len() / 4 * 3);
    let mut start = 0;
    for (q, quad) in clean.chunks(4).enumerate() {
        let end = (q * 4 + quad.len()).min(clean.len());
        if quad.contains(&b'=') || end == clean.len() {
            engine
                .decode_vec(&clean[start..end], &mut out)
                .map_err(|e| format!("bad base64 at character {start}: {e}"))?;
            start = end;
        }
    }
    Ok(out)
}

fn to_f64(bytes: &[u8], ty: NumType, big: bool) -> Vec<f64> {
    macro_rules! conv {
        ($t:ty, $n:expr) => {
            bytes
                .chunks_exact($n)
                .map(|c| {
                    let mut a = [0u8; $n];
                    a.copy_from_slice(c);
                    (if big {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    }) as f64
                })
                .collect()
        };
    }
    match ty {
        NumType::I8 => conv!(i8, 1),
        NumType::U8 => conv!(u8, 1),
        NumType::I16 => conv!(i16, 2),
        NumType::U16 => conv!(u16, 2),
        NumType::I32 => conv!(i32, 4),
        NumType::U32 => conv!(u32, 4),
        NumType::I64 => conv!(i64, 8),
        NumType::U64 => conv!(u64, 8),
        NumType::F32 => conv!(f32, 4),
        NumType::F64 => conv!(f64, 8),
    }
}

fn find<'a>(piece: &'a Piece, section: Section, name: Option<&str>) -> Option<&'a ArrayDesc> {
    piece
        .arrays
        .iter()
        .find(|a| a.section == section && name.is_none_or(|n| a.name == n))
}

/// Reads a `.vtu`: points, cells and the scalar array `wanted` (or the first one-component
/// point array, else cell array), pieces joined.
pub fn read(path: &Path, wanted: Option<&str>) -> Result<Grid, String> {
    let file = VtuFile::open(path)?;
    let mut grid = Grid::default();
    for (p, piece) in file.meta.pieces.iter().enumerate() {
        let at = |e: String| {
            if file.meta.pieces.len() > 1 {
                format!("piece {p}: {e}")
            } else {
                e
            }
        };
        let points =
            find(piece, Section::Points, None).ok_or_else(|| at("no <Points> array".into()))?;
        if points.components != 3 {
            return Err(at(format!("points have {} components", points.components)));
        }
        let coords = file.values(points, piece.points * 3).map_err(at)?;
        let cell_array = |name: &str| {
            find(piece, Section::Cells, Some(name))
                .ok_or_else(|| at(format!("<Cells> has no {name} array")))
        };
        let types = file.values(cell_array("types")?, piece.cells).map_err(at)?;
        let offsets = file
            .values(cell_array("offsets")?, piece.cells)
            .map_err(at)?;
        let corners = offsets.last().copied().unwrap_or(0.0);
        if !(corners >= 0.0 && corners.fract() == 0.0) {
            return Err(at(format!("the last cell offset is {corners}")));
        }
        let connectivity = file
            .values(cell_array("connectivity")?, corners as usize)
            .map_err(at)?;
        let names = |s: Section| -> Vec<(String, usize)> {
            piece
                .arrays
                .iter()
                .filter(|a| a.section == s)
                .map(|a| (a.name.clone(), a.components))
                .collect()
        };
        let picked = pick_array(
            &names(Section::PointData),
            &names(Section::CellData),
            grid.picked.as_ref().map_or(wanted, |p| Some(p.name())),
        )
        .map_err(at)?;
        let (section, count) = match &picked {
            Picked::Point(_) => (Section::PointData, piece.points),
            Picked::Cell(_) => (Section::CellData, piece.cells),
        };
        let desc = find(piece, section, Some(picked.name()))
            .ok_or_else(|| at(format!("no array {:?}", picked.name())))?;
        let scalars = file.values(desc, count).map_err(at)?;
        grid.append(&coords, &connectivity, &offsets, &types, picked, scalars)
            .map_err(at)?;
    }
    Ok(grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_in_padded_segments_decodes_as_one_stream() {
        let e = base64::engine::general_purpose::STANDARD;
        let text = format!(
            "{}\n  {}",
            e.encode([4u8, 0, 0, 0]),
            e.encode([1u8, 2, 3, 4, 5])
        );
        assert_eq!(
            base64_segments(text.as_bytes()).expect("decodes"),
            vec![4, 0, 0, 0, 1, 2, 3, 4, 5]
        );
        let whole = e.encode([4u8, 0, 0, 0, 1, 2, 3, 4]);
        assert_eq!(
            base64_segments(whole.as_bytes()).expect("decodes"),
            vec![4, 0, 0, 0, 1, 2, 3, 4]
        );
        assert!(base64_segments(b"@@@@").is_err());
    }

    #[test]
    fn a_block_inflates_to_its_declared_size_or_is_refused_without_reserving_it() {
        use std::io::Write;
        let raw: Vec<u8> = (0..40_000u32).map(|i| (i % 7) as u8).collect();
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&raw).expect("zlib writes");
        let zlib = z.finish().expect("zlib finishes");
        let lz4 = lz4_flex::block::compress(&raw);
        let mut xz = Vec::new();
        lzma_rs::xz_compress(&mut &raw[..], &mut xz).expect("xz writes");
        for (compressor, input) in [
            (Compressor::Zlib, &zlib),
            (Compressor::Lz4, &lz4),
            (Compressor::Lzma, &xz),
        ] {
            let name = format!("{compressor:?}");
            assert_eq!(
                inflate(compressor, input, raw.len()).as_ref(),
                Ok(&raw),
                "{name}"
            );
            // Declared one byte short or long: refused, naming both sizes.
            let e = inflate(compressor, input, raw.len() - 1).expect_err("one byte short");
            assert!(e.contains("39999") || e.contains("xz:"), "{name}: {e}");
            let e = inflate(compressor, input, raw.len() + 1).expect_err("one byte long");
            assert!(e.contains("40001"), "{name}: {e}");
            // A header declaring 12 GB for the same bytes (the fuzzed `.vtu` that made the
            // reader ask for it at once) is refused too.
            let e = inflate(compressor, input, 12_000_000_000).expect_err("12 GB");
            assert!(e.contains("12000000000"), "{name}: {e}");
        }
        let e = inflate(Compressor::Lz4, &lz4, lz4.len() * 255 + 17).expect_err("past 255×");
        assert!(e.contains("more than LZ4's"), "{e}");
    }
}
