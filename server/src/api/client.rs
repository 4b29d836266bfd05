//! A small blocking HTTP/1.1 client for the REST API, used by `isoray push`, the store
//! benchmark and the tests. It streams request bodies from any reader, so a large step is
//! never held in memory, and it reads the answer even when the server refuses the body early.
//! Plain `http://` only: put TLS in front with a proxy.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::time::Duration;

/// What the server answered.
#[derive(Debug)]
pub struct Response {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Response {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    pub fn json<T: serde::de::DeserializeOwned>(&self) -> Result<T, ClientError> {
        serde_json::from_slice(&self.body)
            .map_err(|e| ClientError::Decode(format!("{e}: {}", self.text())))
    }
}

/// Why a request failed before an answer arrived.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("bad URL `{0}`: expected http://host:port[/path]")]
    Url(String),
    #[error("connection failed: {0}")]
    Io(#[from] std::io::Error),
    #[error("unreadable answer: {0}")]
    Decode(String),
}

/// A request body.
pub enum Body<'a> {
    Empty,
    Bytes(&'a [u8]),
    /// `len` bytes from a reader, streamed.
    Reader(&'a mut dyn Read, u64),
}

/// A server's base address, `http://host:port`.
#[derive(Clone, Debug)]
pub struct Client {
    host: String,
    pub timeout: Duration,
}

impl Client {
    pub fn new(base_url: &str) -> Result<Client, ClientError> {
        let rest = base_url
            .strip_prefix("http://")
            .ok_or_else(|| ClientError::Url(base_url.to_string()))?;
        let host = rest.split('/').next().unwrap_or_default();
        if host.is_empty() {
            return Err(ClientError::Url(base_url.to_string()));
        }
        Ok(Client {
            host: host.to_string(),
            timeout: Duration::from_secs(300),
        })
    }

    /// A connection to the first of the host's addresses that accepts within the timeout.
    fn connect(&self) -> std::io::Result<TcpStream> {
        use std::net::ToSocketAddrs;
        let mut last = None;
        for addr in self.host.to_socket_addrs()? {
            match TcpStream::connect_timeout(&addr, self.timeout) {
                Ok(s) => return Ok(s),
                Err(e) => last = Some(e),
            }
        }
        Err(last.unwrap_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::NotFound, "the host has no address")
        }))
    }

    /// Sends one request on a fresh connection and reads the whole answer.
    pub fn request(
        &self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
        body: Body<'_>,
    ) -> Result<Response, ClientError> {
        let stream = self.connect()?;
        stream.set_read_timeout(Some(self.timeout))?;
        stream.set_write_timeout(Some(self.timeout))?;
        stream.set_nodelay(true)?;
        let len = match &body {
            Body::Empty => 0,
            Body::Bytes(b) => b.len() as u64,
            Body::Reader(_, n) => *n,
        };
        let mut head = format!(
            "{method} {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nContent-Length: {len}\r\n",
            self.host
        );
        for (k, v) in headers {
            head.push_str(&format!("{k}: {v}\r\n"));
        }
        head.push_str("\r\n");
        let mut writer = std::io::BufWriter::with_capacity(1 << 20, &stream);
        // A server that refuses the body stops reading and answers at once; the write then
        // fails, and the answer is still there to read.
        let sent = writer
            .write_all(head.as_bytes())
            .and_then(|()| match body {
                Body::Empty => Ok(()),
                Body::Bytes(b) => writer.write_all(b),
                Body::Reader(r, n) => {
                    let copied = std::io::copy(&mut r.take(n), &mut writer)?;
                    if copied < n {
                        return Err(std::io::Error::new(
                            std::io::ErrorKind::UnexpectedEof,
                            format!("the body reader ended after {copied} of {n} bytes"),
                        ));
                    }
                    Ok(())
                }
            })
            .and_then(|()| writer.flush());
        drop(writer);
        match read_response(&stream) {
            Ok(r) => Ok(r),
            Err(read_err) => Err(match sent {
                Err(e) => ClientError::Io(e),
                Ok(()) => read_err,
            }),
        }
    }
}

fn read_response(stream: &TcpStream) -> Result<Response, ClientError> {
    let mut reader = BufReader::new(stream);
    let mut line = String::new();
    reader.read_line(&mut line)?;
    let status = line
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse::<u16>().ok())
        .ok_or_else(|| ClientError::Decode(format!("status line `{}`", line.trim())))?;
    let mut headers = Vec::new();
    loop {
        line.clear();
        reader.read_line(&mut line)?;
        let l = line.trim_end();
        if l.is_empty() {
            break;
        }
        if let Some((k, v)) = l.split_once(':') {
            headers.push((k.trim().to_string(), v.trim().to_string()));
        }
    }
    let find = |name: &str| {
        headers
            .iter()
            .find(|(k, _): &&(String, String)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.clone())
    };
    let mut body = Vec::new();
    if let Some(n) = find("content-length").and_then(|v| v.parse::<u64>().ok()) {
        reader.take(n).read_to_end(&mut body)?;
    } else if find("transfer-encoding").is_some_and(|v| v.eq_ignore_ascii_case("chunked")) {
        loop {
            line.clear();
            reader.read_line(&mut line)?;
            let size = u64::from_str_radix(line.trim().split(';').next().unwrap_or("0"), 16)
                .map_err(|_| ClientError::Decode("bad chunk size".into()))?;
            if size == 0 {
                break;
            }
            (&mut reader).take(size).read_to_end(&mut body)?;
            line.clear();
            reader.read_line(&mut line)?;
        }
    } else {
        reader.read_to_end(&mut body)?;
    }
    Ok(Response {
        status,
        headers,
        body,
    })
}

/// A `.npy` (version 1) header for a C-ordered little-endian f32 array of `rows × columns`.
pub fn npy_header_f32(rows: u64, columns: u32) -> Vec<u8> {
    npy_header("<f4", rows, u64::from(columns))
}

/// A `.npy` (version 1) header for a C-ordered array of `rows × columns` values of the NumPy
/// type `descr` (`<f4`, `<f8`, `<i8`, ...).
pub fn npy_header(descr: &str, rows: u64, columns: u64) -> Vec<u8> {
    let mut dict =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({rows}, {columns}), }}");
    while (10 + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}
