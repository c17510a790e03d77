//! A small driver for a real headless Chromium over the Chrome DevTools Protocol: the viewer's
//! end-to-end tests and `iwsim bench viewer` load the page in it, wait on the page's own state,
//! click its buttons and take screenshots.
//!
//! Chromium is started with `--remote-debugging-port=0` and prints the browser's WebSocket
//! address on stderr; the driver opens one page target, attaches to it with a flat session
//! and sends commands on that one socket, skipping the events it did not ask for.

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tungstenite::{Message, WebSocket};

/// Flags for a headless Chromium with no GPU, no network chatter and software WebGL.
///
/// Without the background-networking flags Chromium tries Google's hosts at every start; with
/// `--disable-gpu` alone WebGL contexts fail, so WebGL goes through ANGLE's SwiftShader.
pub const CHROMIUM_FLAGS: &[&str] = &[
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--mute-audio",
    "--hide-scrollbars",
];

/// Why the browser could not do what was asked.
#[derive(Debug, thiserror::Error)]
pub enum BrowserError {
    /// No Chromium binary was found.
    #[error("no Chromium found (tried {tried}); install Debian's `chromium` or set IWSIM_CHROMIUM")]
    NotInstalled {
        /// Names tried.
        tried: String,
    },
    /// Chromium did not come up.
    #[error("Chromium did not start: {0}")]
    Start(String),
    /// The DevTools socket failed.
    #[error("DevTools connection: {0}")]
    Socket(String),
    /// A DevTools command returned an error.
    #[error("{method}: {message}")]
    Command {
        /// The method sent.
        method: String,
        /// What Chromium said.
        message: String,
    },
    /// A script threw in the page.
    #[error("the page threw: {0}")]
    Script(String),
    /// A wait ran out.
    #[error("timed out after {0:?} waiting for {1}")]
    Timeout(Duration, String),
}

/// The Chromium process and its throw-away profile, removed however the driver ends.
#[derive(Debug)]
struct Process {
    child: Child,
    profile: PathBuf,
}

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.profile);
    }
}

/// A running headless Chromium with one page.
#[derive(Debug)]
pub struct Browser {
    ws: WebSocket<TcpStream>,
    session_id: String,
    next_id: u64,
    _process: Process,
}

impl Browser {
    /// Starts Chromium with a fresh profile and a `width` × `height` page.
    pub fn launch(width: u32, height: u32) -> Result<Self, BrowserError> {
        let exe = find_chromium()?;
        let profile = std::env::temp_dir().join(format!(
            "iwsim-chromium-{}-{}",
            std::process::id(),
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos())
        ));
        std::fs::create_dir_all(&profile).map_err(|e| BrowserError::Start(format!("{}: {e}", profile.display())))?;
        let child = Command::new(&exe)
            .args(CHROMIUM_FLAGS)
            .arg("--remote-debugging-port=0")
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg(format!("--window-size={width},{height}"))
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn();
        let mut process = match child {
            Ok(child) => Process { child, profile },
            Err(e) => {
                let _ = std::fs::remove_dir_all(&profile);
                return Err(BrowserError::Start(format!("{exe}: {e}")));
            }
        };
        // Chromium announces its DevTools address on stderr; read until it does (or exits).
        let stderr = process.child.stderr.take().ok_or_else(|| BrowserError::Start("no stderr".into()))?;
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut sent = false;
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if !sent && let Some(at) = line.find("ws://") {
                    let _ = tx.send(line[at..].trim().to_owned());
                    sent = true;
                }
                // Keep draining so Chromium never blocks on a full pipe.
            }
        });
        let url = rx
            .recv_timeout(Duration::from_secs(30))
            .map_err(|_| BrowserError::Start("no DevTools address on stderr within 30 s".into()))?;
        let mut b = Self { ws: connect(&url)?, session_id: String::new(), next_id: 1, _process: process };
        let target = b.call("Target.createTarget", json!({ "url": "about:blank" }))?;
        let target_id = target["targetId"].as_str().unwrap_or_default().to_owned();
        let attached = b.call("Target.attachToTarget", json!({ "targetId": target_id, "flatten": true }))?;
        b.session_id = attached["sessionId"].as_str().unwrap_or_default().to_owned();
        b.call(
            "Emulation.setDeviceMetricsOverride",
            json!({ "width": width, "height": height, "deviceScaleFactor": 1, "mobile": false }),
        )?;
        b.call("Page.enable", json!({}))?;
        b.call("Runtime.enable", json!({}))?;
        Ok(b)
    }

    /// Sends one DevTools command to the page and returns its result.
    pub fn call(&mut self, method: &str, params: Value) -> Result<Value, BrowserError> {
        let id = self.next_id;
        self.next_id += 1;
        let mut msg = json!({ "id": id, "method": method, "params": params });
        if !self.session_id.is_empty() {
            msg["sessionId"] = json!(self.session_id);
        }
        self.ws.send(Message::text(msg.to_string())).map_err(|e| BrowserError::Socket(e.to_string()))?;
        loop {
            let text = match self.ws.read().map_err(|e| BrowserError::Socket(format!("{method}: {e}")))? {
                Message::Text(t) => t,
                Message::Close(_) => return Err(BrowserError::Socket("Chromium closed the connection".into())),
                _ => continue,
            };
            let v: Value = serde_json::from_str(text.as_str()).map_err(|e| BrowserError::Socket(e.to_string()))?;
            if v["id"].as_u64() != Some(id) {
                continue; // an event, or an answer to nothing we wait for
            }
            if let Some(err) = v.get("error") {
                return Err(BrowserError::Command {
                    method: method.to_owned(),
                    message: err["message"].as_str().unwrap_or("error").to_owned(),
                });
            }
            return Ok(v["result"].clone());
        }
    }

    /// Loads `url` and waits until its document has loaded.
    pub fn navigate(&mut self, url: &str) -> Result<(), BrowserError> {
        self.call("Page.navigate", json!({ "url": url }))?;
        self.wait_for("document.readyState === 'complete'", Duration::from_secs(20)).map(|_| ())
    }

    /// Evaluates `expression` in the page (awaiting it if it is a promise) and returns its value.
    pub fn eval(&mut self, expression: &str) -> Result<Value, BrowserError> {
        let r = self.call(
            "Runtime.evaluate",
            json!({ "expression": expression, "awaitPromise": true, "returnByValue": true }),
        )?;
        if let Some(ex) = r.get("exceptionDetails") {
            let text = ex["exception"]["description"].as_str().or(ex["text"].as_str()).unwrap_or("exception");
            return Err(BrowserError::Script(text.to_owned()));
        }
        Ok(r["result"]["value"].clone())
    }

    /// Waits, inside the page, until `condition` (a JavaScript expression) is truthy, checking
    /// once per animation frame; returns its value. The page's own state is the signal: no
    /// fixed sleeps.
    pub fn wait_for(&mut self, condition: &str, timeout: Duration) -> Result<Value, BrowserError> {
        let ms = timeout.as_millis();
        let js = format!(
            "new Promise((ok) => {{ const until = performance.now() + {ms}; const check = () => {{ \
             let v; try {{ v = ({condition}); }} catch (e) {{ v = undefined; }} \
             if (v) ok({{ v }}); else if (performance.now() > until) ok(null); \
             else (document.hidden ? setTimeout(check, 16) : requestAnimationFrame(check)); }}; check(); }})"
        );
        let started = Instant::now();
        let v = self.eval(&js)?;
        if v.is_null() {
            return Err(BrowserError::Timeout(started.elapsed(), condition.to_owned()));
        }
        Ok(v["v"].clone())
    }

    /// Clicks the centre of the first element matching `selector` with real mouse events.
    pub fn click(&mut self, selector: &str) -> Result<(), BrowserError> {
        let sel = serde_json::to_string(selector).unwrap_or_default();
        let at = self.eval(&format!(
            "(() => {{ const r = document.querySelector({sel}).getBoundingClientRect(); \
             return [r.left + r.width / 2, r.top + r.height / 2]; }})()"
        ))?;
        let (x, y) = (at[0].as_f64().unwrap_or(0.0), at[1].as_f64().unwrap_or(0.0));
        for kind in ["mousePressed", "mouseReleased"] {
            self.call(
                "Input.dispatchMouseEvent",
                json!({ "type": kind, "x": x, "y": y, "button": "left", "clickCount": 1 }),
            )?;
        }
        Ok(())
    }

    /// A PNG screenshot of the page as it is now.
    pub fn screenshot_png(&mut self) -> Result<Vec<u8>, BrowserError> {
        let r = self.call("Page.captureScreenshot", json!({ "format": "png" }))?;
        let data = r["data"].as_str().unwrap_or_default();
        base64_decode(data).ok_or_else(|| BrowserError::Socket("screenshot is not base64".into()))
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.ws.close(None);
    }
}

fn connect(url: &str) -> Result<WebSocket<TcpStream>, BrowserError> {
    let rest = url.strip_prefix("ws://").ok_or_else(|| BrowserError::Start(format!("odd address {url}")))?;
    let host = rest.split('/').next().unwrap_or_default();
    let stream = TcpStream::connect(host).map_err(|e| BrowserError::Socket(format!("{host}: {e}")))?;
    // A page that hangs must fail the caller, not hang it.
    stream.set_read_timeout(Some(Duration::from_secs(60))).map_err(|e| BrowserError::Socket(e.to_string()))?;
    let (ws, _) = tungstenite::client(url, stream).map_err(|e| BrowserError::Socket(e.to_string()))?;
    Ok(ws)
}

fn find_chromium() -> Result<String, BrowserError> {
    let mut tried = Vec::new();
    let candidates = std::env::var("IWSIM_CHROMIUM")
        .into_iter()
        .chain(["chromium", "chromium-browser", "google-chrome", "google-chrome-stable"].map(str::to_owned));
    for name in candidates {
        let found = if name.contains('/') {
            std::path::Path::new(&name).is_file()
        } else {
            std::env::var_os("PATH").is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(&name).is_file()))
        };
        if found {
            return Ok(name);
        }
        tried.push(name);
    }
    Err(BrowserError::NotInstalled { tried: tried.join(", ") })
}

/// Standard base64 (with padding), as DevTools sends screenshots.
fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let val = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let s = s.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    for chunk in s.chunks(4) {
        let mut n = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            n |= val(c)? << (18 - 6 * i);
        }
        let bytes = n.to_be_bytes();
        match chunk.len() {
            4 => out.extend_from_slice(&bytes[1..4]),
            3 => out.extend_from_slice(&bytes[1..3]),
            2 => out.push(bytes[1]),
            _ => return None,
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::base64_decode;

    #[test]
    fn base64_decodes_with_and_without_padding() {
        assert_eq!(base64_decode("aXdzaW0=").as_deref(), Some(&b"iwsim"[..]));
        assert_eq!(base64_decode("aXdzaW1z").as_deref(), Some(&b"iwsims"[..]));
        assert_eq!(base64_decode("aXc=").as_deref(), Some(&b"iw"[..]));
        assert_eq!(base64_decode("a"), None);
        assert_eq!(base64_decode("a!=="), None);
    }
}
