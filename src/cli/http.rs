//! A minimal blocking HTTP/1.1 client over `std::net::TcpStream` for `rbfsurf submit`: one request
//! per connection (`Connection: close`), `Content-Length` or chunked responses, plain `http://`
//! only (put a TLS-terminating proxy in front for https). No dependencies beyond std.

use anyhow::{Context, Result, bail};
use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::time::Duration;

/// A server base URL split into its parts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BaseUrl {
    /// `host:port`.
    pub authority: String,
    /// Host name for the `Host` header.
    pub host: String,
    /// Path prefix without a trailing slash (usually empty).
    pub prefix: String,
}

impl BaseUrl {
    /// Parses `http://host[:port][/prefix]`.
    pub fn parse(url: &str) -> Result<BaseUrl> {
        let Some(rest) = url.strip_prefix("http://") else {
            if url.starts_with("https://") {
                bail!(
                    "{url}: https is not supported by `submit`; use http:// (e.g. behind a TLS proxy on the same host)"
                );
            }
            bail!("{url}: give the server as http://host:port");
        };
        let (auth, path) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
        if auth.is_empty() {
            bail!("{url}: no host");
        }
        let host = auth.to_string();
        let authority = if auth.contains(':') && !auth.ends_with(']') {
            auth.to_string()
        } else {
            format!("{auth}:80")
        };
        Ok(BaseUrl {
            authority,
            host,
            prefix: path.trim_end_matches('/').to_string(),
        })
    }
}

/// A received response.
#[derive(Debug)]
pub struct HttpResponse {
    /// Status code.
    pub status: u16,
    /// Headers (names lower-cased).
    pub headers: Vec<(String, String)>,
    /// Body (de-chunked).
    pub body: Vec<u8>,
}

impl HttpResponse {
    /// A header's value (name in lower case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    /// The body as JSON.
    pub fn json(&self) -> Result<serde_json::Value> {
        serde_json::from_slice(&self.body).with_context(|| {
            format!(
                "HTTP {}: the server did not answer JSON: {}",
                self.status,
                String::from_utf8_lossy(&self.body[..self.body.len().min(200)])
            )
        })
    }
}

/// Sends one request and reads the whole response.
pub fn request(
    base: &BaseUrl,
    method: &str,
    path_and_query: &str,
    headers: &[(&str, String)],
    body: &[u8],
    timeout: Duration,
) -> Result<HttpResponse> {
    let mut stream = TcpStream::connect(&base.authority)
        .with_context(|| format!("cannot connect to {}", base.authority))?;
    stream.set_read_timeout(Some(timeout))?;
    stream.set_write_timeout(Some(timeout))?;
    let mut head = format!(
        "{method} {}{path_and_query} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nContent-Length: {}\r\nUser-Agent: rbfsurf/{}\r\n",
        base.prefix,
        base.host,
        body.len(),
        env!("CARGO_PKG_VERSION")
    );
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    stream.write_all(head.as_bytes())?;
    // The server may answer early (413, 401) and close; the response is still worth reading.
    let _ = stream.write_all(body);
    read_response(BufReader::new(stream))
}

fn read_response(mut r: impl BufRead) -> Result<HttpResponse> {
    let mut line = String::new();
    r.read_line(&mut line)
        .context("no response from the server")?;
    let status = line
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse::<u16>().ok())
        .with_context(|| format!("malformed status line {line:?}"))?;
    let mut headers = Vec::new();
    loop {
        line.clear();
        r.read_line(&mut line)?;
        let l = line.trim_end();
        if l.is_empty() {
            break;
        }
        if let Some((k, v)) = l.split_once(':') {
            headers.push((k.trim().to_ascii_lowercase(), v.trim().to_string()));
        }
    }
    let get = |name: &str| {
        headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    };
    let body = if get("transfer-encoding").is_some_and(|v| v.eq_ignore_ascii_case("chunked")) {
        read_chunked(&mut r)?
    } else if let Some(n) = get("content-length").and_then(|v| v.parse::<usize>().ok()) {
        let mut b = vec![0; n];
        r.read_exact(&mut b).context("response body cut short")?;
        b
    } else {
        let mut b = Vec::new();
        r.read_to_end(&mut b)?;
        b
    };
    Ok(HttpResponse {
        status,
        headers,
        body,
    })
}

fn read_chunked(r: &mut impl BufRead) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut line = String::new();
    loop {
        line.clear();
        r.read_line(&mut line)?;
        let size_hex = line.trim().split(';').next().unwrap_or("");
        let size = usize::from_str_radix(size_hex, 16)
            .with_context(|| format!("malformed chunk size {size_hex:?}"))?;
        if size == 0 {
            return Ok(out);
        }
        let start = out.len();
        out.resize(start + size, 0);
        r.read_exact(&mut out[start..])?;
        line.clear();
        r.read_line(&mut line)?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_and_responses_parse() {
        let b = BaseUrl::parse("http://127.0.0.1:8080/").unwrap();
        assert_eq!(b.authority, "127.0.0.1:8080");
        assert_eq!(b.prefix, "");
        let b = BaseUrl::parse("http://example.org/api/").unwrap();
        assert_eq!(b.authority, "example.org:80");
        assert_eq!(b.prefix, "/api");
        assert!(BaseUrl::parse("https://x").is_err());
        assert!(BaseUrl::parse("ftp://x").is_err());
        let raw = b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n3\r\nabc\r\n2\r\nde\r\n0\r\n\r\n";
        let r = read_response(&raw[..]).unwrap();
        assert_eq!((r.status, r.body.as_slice()), (200, &b"abcde"[..]));
        let raw = b"HTTP/1.1 413 Payload Too Large\r\ncontent-length: 2\r\n\r\n{}";
        let r = read_response(&raw[..]).unwrap();
        assert_eq!((r.status, r.body.as_slice()), (413, &b"{}"[..]));
    }
}
