//! The XML-RPC the ROS master and nodes speak: values, calls and responses as XML text, a
//! blocking HTTP/1.1 client (one request per connection) and a small threaded server.
//!
//! Only what the ROS 1 master and node APIs use is supported: `int`/`i4`, `boolean`, `string`
//! (also untyped values), `double`, `array`, `struct`, `base64` (kept as text) and `nil`.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream, ToSocketAddrs};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// An XML-RPC value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `<int>` / `<i4>`.
    Int(i32),
    /// `<boolean>`.
    Bool(bool),
    /// `<string>`, or a value without a type tag.
    Str(String),
    /// `<double>`.
    Double(f64),
    /// `<array>`.
    Array(Vec<Value>),
    /// `<struct>`.
    Struct(Vec<(String, Value)>),
    /// `<nil/>`.
    Nil,
}

impl Value {
    /// The integer, if it is one.
    pub fn as_i32(&self) -> Option<i32> {
        match self {
            Value::Int(i) => Some(*i),
            _ => None,
        }
    }

    /// The string, if it is one.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// The elements, if it is an array.
    pub fn as_array(&self) -> Option<&[Value]> {
        match self {
            Value::Array(a) => Some(a),
            _ => None,
        }
    }

    fn write(&self, out: &mut String) {
        out.push_str("<value>");
        match self {
            Value::Int(i) => out.push_str(&format!("<int>{i}</int>")),
            Value::Bool(b) => out.push_str(&format!("<boolean>{}</boolean>", *b as u8)),
            Value::Str(s) => {
                out.push_str("<string>");
                escape(s, out);
                out.push_str("</string>");
            }
            Value::Double(d) => out.push_str(&format!("<double>{d}</double>")),
            Value::Array(a) => {
                out.push_str("<array><data>");
                for v in a {
                    v.write(out);
                }
                out.push_str("</data></array>");
            }
            Value::Struct(m) => {
                out.push_str("<struct>");
                for (k, v) in m {
                    out.push_str("<member><name>");
                    escape(k, out);
                    out.push_str("</name>");
                    v.write(out);
                    out.push_str("</member>");
                }
                out.push_str("</struct>");
            }
            Value::Nil => out.push_str("<nil/>"),
        }
        out.push_str("</value>");
    }
}

impl From<&str> for Value {
    fn from(s: &str) -> Self {
        Value::Str(s.to_string())
    }
}

impl From<String> for Value {
    fn from(s: String) -> Self {
        Value::Str(s)
    }
}

impl From<i32> for Value {
    fn from(i: i32) -> Self {
        Value::Int(i)
    }
}

impl From<Vec<Value>> for Value {
    fn from(a: Vec<Value>) -> Self {
        Value::Array(a)
    }
}

fn escape(s: &str, out: &mut String) {
    for c in s.chars() {
        match c {
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '&' => out.push_str("&amp;"),
            c => out.push(c),
        }
    }
}

fn unescape(s: &str) -> Result<String, String> {
    if !s.contains('&') {
        return Ok(s.to_string());
    }
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find('&') {
        out.push_str(&rest[..i]);
        let end = rest[i..]
            .find(';')
            .ok_or_else(|| "an `&` entity without `;`".to_string())?;
        let ent = &rest[i + 1..i + end];
        match ent {
            "lt" => out.push('<'),
            "gt" => out.push('>'),
            "amp" => out.push('&'),
            "quot" => out.push('"'),
            "apos" => out.push('\''),
            _ => {
                let code = if let Some(h) = ent.strip_prefix("#x") {
                    u32::from_str_radix(h, 16).ok()
                } else if let Some(d) = ent.strip_prefix('#') {
                    d.parse().ok()
                } else {
                    None
                };
                out.push(
                    code.and_then(char::from_u32)
                        .ok_or_else(|| format!("unknown entity `&{ent};`"))?,
                );
            }
        }
        rest = &rest[i + end + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

/// An XML element: name and children (elements and text).
#[derive(Debug)]
struct Element {
    name: String,
    children: Vec<Node>,
}

#[derive(Debug)]
enum Node {
    Element(Element),
    Text(String),
}

impl Element {
    fn elements(&self) -> impl Iterator<Item = &Element> {
        self.children.iter().filter_map(|c| match c {
            Node::Element(e) => Some(e),
            Node::Text(_) => None,
        })
    }

    fn child(&self, name: &str) -> Result<&Element, String> {
        self.elements()
            .find(|e| e.name == name)
            .ok_or_else(|| format!("<{}> has no <{name}>", self.name))
    }

    fn text(&self) -> String {
        self.children
            .iter()
            .filter_map(|c| match c {
                Node::Text(t) => Some(t.as_str()),
                Node::Element(_) => None,
            })
            .collect()
    }
}

/// Parses an XML document into its root element (no namespaces, no DTDs, no attributes kept).
fn parse_xml(doc: &str) -> Result<Element, String> {
    let mut stack: Vec<Element> = vec![Element {
        name: String::new(),
        children: Vec::new(),
    }];
    let mut rest = doc;
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix('<') {
            if after.starts_with('?') || after.starts_with('!') {
                let end = if after.starts_with("!--") { "-->" } else { ">" };
                let i = after
                    .find(end)
                    .ok_or_else(|| "an unterminated declaration or comment".to_string())?;
                rest = &after[i + end.len()..];
                continue;
            }
            let i = after
                .find('>')
                .ok_or_else(|| "an unterminated tag".to_string())?;
            let tag = &after[..i];
            rest = &after[i + 1..];
            if let Some(name) = tag.strip_prefix('/') {
                let e = stack
                    .pop()
                    .filter(|_| !stack.is_empty())
                    .ok_or("a stray closing tag")?;
                if e.name != name.trim() {
                    return Err(format!("<{}> closed by </{}>", e.name, name.trim()));
                }
                stack
                    .last_mut()
                    .expect("root stays")
                    .children
                    .push(Node::Element(e));
            } else {
                let empty = tag.ends_with('/');
                let tag = tag.trim_end_matches('/');
                let name = tag.split_whitespace().next().unwrap_or("").to_string();
                let e = Element {
                    name,
                    children: Vec::new(),
                };
                if empty {
                    stack
                        .last_mut()
                        .expect("root stays")
                        .children
                        .push(Node::Element(e));
                } else {
                    stack.push(e);
                }
            }
        } else {
            let i = rest.find('<').unwrap_or(rest.len());
            let text = unescape(&rest[..i])?;
            stack
                .last_mut()
                .expect("root stays")
                .children
                .push(Node::Text(text));
            rest = &rest[i..];
        }
    }
    if stack.len() != 1 {
        return Err(format!(
            "<{}> is not closed",
            stack.last().map_or("", |e| e.name.as_str())
        ));
    }
    let root = stack.pop().expect("one");
    root.children
        .into_iter()
        .find_map(|c| match c {
            Node::Element(e) => Some(e),
            Node::Text(_) => None,
        })
        .ok_or_else(|| "no root element".to_string())
}

fn parse_value(v: &Element) -> Result<Value, String> {
    let Some(t) = v.elements().next() else {
        return Ok(Value::Str(v.text()));
    };
    let text = t.text();
    let num = |s: &str| -> Result<i32, String> {
        s.trim()
            .parse()
            .map_err(|_| format!("`{s}` is not an <{}>", t.name))
    };
    Ok(match t.name.as_str() {
        "int" | "i4" => Value::Int(num(&text)?),
        "boolean" => Value::Bool(num(&text)? != 0),
        "string" | "base64" => Value::Str(text),
        "double" => Value::Double(
            text.trim()
                .parse()
                .map_err(|_| format!("`{text}` is not a <double>"))?,
        ),
        "nil" => Value::Nil,
        "array" => Value::Array(
            t.child("data")?
                .elements()
                .filter(|e| e.name == "value")
                .map(parse_value)
                .collect::<Result<_, _>>()?,
        ),
        "struct" => Value::Struct(
            t.elements()
                .filter(|e| e.name == "member")
                .map(|m| Ok((m.child("name")?.text(), parse_value(m.child("value")?)?)))
                .collect::<Result<_, String>>()?,
        ),
        other => return Err(format!("unsupported XML-RPC type <{other}>")),
    })
}

fn params(root: &Element) -> Result<Vec<Value>, String> {
    match root.child("params") {
        Ok(p) => p
            .elements()
            .filter(|e| e.name == "param")
            .map(|p| parse_value(p.child("value")?))
            .collect(),
        Err(_) => Ok(Vec::new()),
    }
}

/// A `<methodCall>` document.
pub fn call_xml(method: &str, args: &[Value]) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?>\n<methodCall><methodName>");
    escape(method, &mut out);
    out.push_str("</methodName><params>");
    for a in args {
        out.push_str("<param>");
        a.write(&mut out);
        out.push_str("</param>");
    }
    out.push_str("</params></methodCall>\n");
    out
}

/// A `<methodResponse>` document returning `v`.
pub fn response_xml(v: &Value) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?>\n<methodResponse><params><param>");
    v.write(&mut out);
    out.push_str("</param></params></methodResponse>\n");
    out
}

/// A fault `<methodResponse>`.
pub fn fault_xml(code: i32, msg: &str) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?>\n<methodResponse><fault>");
    Value::Struct(vec![
        ("faultCode".into(), Value::Int(code)),
        ("faultString".into(), Value::Str(msg.into())),
    ])
    .write(&mut out);
    out.push_str("</fault></methodResponse>\n");
    out
}

/// Parses a `<methodCall>`: the method name and its arguments.
pub fn parse_call(doc: &str) -> Result<(String, Vec<Value>), String> {
    let root = parse_xml(doc)?;
    if root.name != "methodCall" {
        return Err(format!("expected <methodCall>, got <{}>", root.name));
    }
    Ok((
        root.child("methodName")?.text().trim().to_string(),
        params(&root)?,
    ))
}

/// Parses a `<methodResponse>`: its value, or the fault as an error.
pub fn parse_response(doc: &str) -> Result<Value, String> {
    let root = parse_xml(doc)?;
    if root.name != "methodResponse" {
        return Err(format!("expected <methodResponse>, got <{}>", root.name));
    }
    if let Ok(f) = root.child("fault") {
        return Err(format!(
            "XML-RPC fault: {:?}",
            parse_value(f.child("value")?)?
        ));
    }
    params(&root)?
        .into_iter()
        .next()
        .ok_or_else(|| "the response has no value".to_string())
}

/// `http://host:port/path` split into host, port and path.
pub fn split_uri(uri: &str) -> Result<(String, u16, String), String> {
    let rest = uri
        .strip_prefix("http://")
        .ok_or_else(|| format!("`{uri}` is not an http:// URI"))?;
    let (hostport, path) = match rest.find('/') {
        Some(i) => (&rest[..i], &rest[i..]),
        None => (rest, "/"),
    };
    let (host, port) = match hostport.rsplit_once(':') {
        Some((h, p)) if !h.ends_with(']') || h.starts_with('[') => (
            h,
            p.parse::<u16>()
                .map_err(|_| format!("`{uri}` has a bad port `{p}`"))?,
        ),
        _ => (hostport, 80),
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() {
        return Err(format!("`{uri}` has no host"));
    }
    Ok((host.to_string(), port, path.to_string()))
}

/// Calls `method` at `uri` and returns the response value (for ROS APIs, `[code, msg, value]`).
pub fn call(uri: &str, method: &str, args: &[Value], timeout: Duration) -> Result<Value, String> {
    let (host, port, path) = split_uri(uri)?;
    let addr = (host.as_str(), port)
        .to_socket_addrs()
        .map_err(|e| format!("cannot resolve `{host}`: {e}"))?
        .next()
        .ok_or_else(|| format!("`{host}` resolves to no address"))?;
    let mut s = TcpStream::connect_timeout(&addr, timeout)
        .map_err(|e| format!("cannot connect to {uri}: {e}"))?;
    s.set_read_timeout(Some(timeout)).ok();
    s.set_write_timeout(Some(timeout)).ok();
    s.set_nodelay(true).ok();
    let body = call_xml(method, args);
    let req = format!(
        "POST {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUser-Agent: perturb-bridge\r\nContent-Type: text/xml\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    s.write_all(req.as_bytes())
        .map_err(|e| format!("{method} to {uri}: {e}"))?;
    let (status, body) =
        read_http(&mut BufReader::new(s)).map_err(|e| format!("{method} to {uri}: {e}"))?;
    if !status.contains(" 200") {
        return Err(format!("{method} to {uri}: HTTP `{status}`"));
    }
    parse_response(&body).map_err(|e| format!("{method} to {uri}: {e}"))
}

/// Reads an HTTP message: its first line and its body (Content-Length, or to the end).
fn read_http(r: &mut impl BufRead) -> Result<(String, String), String> {
    let mut first = String::new();
    r.read_line(&mut first).map_err(|e| e.to_string())?;
    if first.is_empty() {
        return Err("the connection closed before a response".into());
    }
    let mut len: Option<usize> = None;
    loop {
        let mut line = String::new();
        r.read_line(&mut line).map_err(|e| e.to_string())?;
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':')
            && k.trim().eq_ignore_ascii_case("content-length")
        {
            len = Some(
                v.trim()
                    .parse()
                    .map_err(|_| format!("bad Content-Length `{v}`"))?,
            );
        }
    }
    let mut body = Vec::new();
    match len {
        Some(n) if n > 64 << 20 => return Err(format!("a body of {n} bytes is too large")),
        Some(n) => {
            body.resize(n, 0);
            r.read_exact(&mut body).map_err(|e| e.to_string())?;
        }
        None => {
            r.take(64 << 20)
                .read_to_end(&mut body)
                .map_err(|e| e.to_string())?;
        }
    }
    let body = String::from_utf8(body).map_err(|_| "the body is not UTF-8".to_string())?;
    Ok((first.trim_end().to_string(), body))
}

/// A handler of XML-RPC calls: method name and arguments to the response value, or a fault.
pub type Handler = dyn Fn(&str, &[Value]) -> Result<Value, String> + Send + Sync;

/// A running XML-RPC server: one thread accepting, one short-lived thread per request.
pub struct Server {
    port: u16,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Server {
    /// Serves `handler` on `bind` (port 0: any free port).
    pub fn start(bind: &str, handler: Arc<Handler>) -> std::io::Result<Server> {
        let listener = TcpListener::bind(bind)?;
        let port = listener.local_addr()?.port();
        listener.set_nonblocking(true)?;
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let thread = std::thread::Builder::new()
            .name("ros1-xmlrpc".into())
            .spawn(move || {
                while !stopped.load(Ordering::Relaxed) {
                    match listener.accept() {
                        Ok((s, _)) => {
                            let h = handler.clone();
                            let _ = std::thread::Builder::new()
                                .name("ros1-xmlrpc-req".into())
                                .spawn(move || serve_one(s, &*h));
                        }
                        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                            std::thread::sleep(Duration::from_millis(20));
                        }
                        Err(e) => {
                            tracing::warn!("ROS 1 XML-RPC server: accept failed: {e}");
                            std::thread::sleep(Duration::from_millis(100));
                        }
                    }
                }
            })?;
        Ok(Server {
            port,
            stop,
            thread: Some(thread),
        })
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.port
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn serve_one(s: TcpStream, handler: &Handler) {
    let _ = s.set_nonblocking(false);
    let _ = s.set_read_timeout(Some(Duration::from_secs(10)));
    let _ = s.set_write_timeout(Some(Duration::from_secs(10)));
    let _ = s.set_nodelay(true);
    let Ok(mut w) = s.try_clone() else { return };
    let (body, status) = match read_http(&mut BufReader::new(s)) {
        Ok((_, req)) => match parse_call(&req) {
            Ok((method, args)) => match handler(&method, &args) {
                Ok(v) => (response_xml(&v), "200 OK"),
                Err(e) => (fault_xml(1, &e), "200 OK"),
            },
            Err(e) => (
                fault_xml(-32700, &format!("bad XML-RPC call: {e}")),
                "200 OK",
            ),
        },
        Err(e) => (e, "400 Bad Request"),
    };
    let resp = format!(
        "HTTP/1.1 {status}\r\nServer: perturb-bridge\r\nContent-Type: text/xml\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = w.write_all(resp.as_bytes());
    let _ = w.flush();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_through_xml() {
        let v = Value::Array(vec![
            Value::Int(1),
            Value::Str("a <b> & c".into()),
            Value::Array(vec![Value::Str("TCPROS".into()), Value::Int(-5)]),
            Value::Bool(true),
            Value::Double(2.5),
            Value::Struct(vec![("k".into(), Value::Nil)]),
        ]);
        assert_eq!(parse_response(&response_xml(&v)).unwrap(), v);
        let (m, args) =
            parse_call(&call_xml("registerPublisher", std::slice::from_ref(&v))).unwrap();
        assert_eq!((m.as_str(), args), ("registerPublisher", vec![v]));
    }

    #[test]
    fn reads_what_python_xmlrpc_writes() {
        // Python's xmlrpc.client: untyped strings, <i4>, whitespace, entities.
        let doc = "<?xml version='1.0'?>\n<methodResponse>\n<params>\n<param>\n<value><array><data>\n<value><i4>1</i4></value>\n<value>ready &amp; set</value>\n<value><array><data>\n<value><string>http://127.0.0.1:4567/</string></value>\n</data></array></value>\n</data></array></value>\n</param>\n</params>\n</methodResponse>\n";
        let v = parse_response(doc).unwrap();
        let a = v.as_array().unwrap();
        assert_eq!(a[0], Value::Int(1));
        assert_eq!(a[1], Value::Str("ready & set".into()));
        assert_eq!(
            a[2].as_array().unwrap()[0].as_str(),
            Some("http://127.0.0.1:4567/")
        );
        let fault = "<?xml version='1.0'?><methodResponse><fault><value><struct><member><name>faultCode</name><value><int>1</int></value></member></struct></value></fault></methodResponse>";
        assert!(parse_response(fault).unwrap_err().contains("fault"));
        assert!(parse_response("<methodResponse><params>").is_err());
    }

    #[test]
    fn uris_split() {
        assert_eq!(
            split_uri("http://127.0.0.1:11311/").unwrap(),
            ("127.0.0.1".into(), 11311, "/".into())
        );
        assert_eq!(
            split_uri("http://localhost:9").unwrap(),
            ("localhost".into(), 9, "/".into())
        );
        assert!(split_uri("https://x:1/").is_err());
    }

    #[test]
    fn a_call_reaches_the_server_and_comes_back() {
        let server = Server::start(
            "127.0.0.1:0",
            Arc::new(|m: &str, a: &[Value]| {
                if m == "echo" {
                    Ok(Value::Array(a.to_vec()))
                } else {
                    Err(format!("no method {m}"))
                }
            }),
        )
        .unwrap();
        let uri = format!("http://127.0.0.1:{}/", server.port());
        let v = call(
            &uri,
            "echo",
            &["x".into(), 3.into()],
            Duration::from_secs(5),
        )
        .unwrap();
        assert_eq!(v, Value::Array(vec!["x".into(), 3.into()]));
        let e = call(&uri, "nope", &[], Duration::from_secs(5)).unwrap_err();
        assert!(e.contains("no method nope"), "{e}");
    }
}
