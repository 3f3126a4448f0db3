//! The page and its files, compiled into the binary: a vehicle has no
//! network to fetch them from, and BlueOS serves the page under a path
//! prefix of its own, so every reference in them is relative ("app.js",
//! "v1/events"), never "/app.js".

/// A file of the page.
pub struct Asset {
    pub ctype: &'static str,
    pub body: &'static [u8],
}

const INDEX: &[u8] = include_bytes!("assets/index.html");
const APP_JS: &[u8] = include_bytes!("assets/app.js");
const STYLE: &[u8] = include_bytes!("assets/style.css");
const ICON: &[u8] = include_bytes!("assets/icon.svg");
/// The API's description, which the tests check the answers against.
pub const OPENAPI: &[u8] = include_bytes!("../../../../../config/blueos/openapi.json");

/// The file served at `path`, if it is one of the page's.
pub fn find(path: &str) -> Option<Asset> {
    let (ctype, body) = match path {
        "/" | "/index.html" => ("text/html; charset=utf-8", INDEX),
        "/app.js" => ("text/javascript; charset=utf-8", APP_JS),
        "/style.css" => ("text/css; charset=utf-8", STYLE),
        "/icon.svg" => ("image/svg+xml", ICON),
        "/v1/openapi.json" => ("application/json", OPENAPI),
        _ => return None,
    };
    Some(Asset { ctype, body })
}

/// BlueOS's contract (`GET /register_service`): what its interface lists
/// the extension as, and that the page works under BlueOS's path prefix.
pub fn register_service() -> String {
    serde_json::json!({
        "name": "lightpose",
        "description": "Pose of the vehicle from a light beacon: the 5 x 5 photodiode image, the pose with its uncertainty, and why it is not ok",
        "icon": "mdi-lighthouse-on",
        "company": "lightpose",
        "version": env!("CARGO_PKG_VERSION"),
        "webpage": "https://github.com/lightpose/lightpose",
        "api": "v1/openapi.json",
        "works_in_relative_paths": true,
    })
    .to_string()
}
