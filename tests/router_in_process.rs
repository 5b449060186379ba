//! The service's router built in process from the library (no binary, no socket): fast tests of handlers,
//! beside the end-to-end tests of the binary in `service.rs`. Each request goes through every layer the server
//! installs on the router (strict queries and bodies, encodings, auth, metrics), as `oneshot` calls.

use axum::body::Body;
use axum::http::{Request, StatusCode};
use clap::Parser;
use kac::service::{config::Config, routes::router, Inner};
use serde_json::{json, Value};
use tower::ServiceExt;

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    config: Config,
}

fn app(dir: &std::path::Path) -> axum::Router {
    let args = Args::parse_from(["kac", "--data-dir", dir.to_str().unwrap()]);
    router(Inner::new(args.config).unwrap())
}

async fn call(app: &axum::Router, req: Request<Body>) -> (StatusCode, Value) {
    let resp = app.clone().oneshot(req).await.unwrap();
    let status = resp.status();
    let bytes = axum::body::to_bytes(resp.into_body(), usize::MAX).await.unwrap();
    (status, serde_json::from_slice(&bytes).unwrap_or(Value::Null))
}

fn post_json(uri: &str, body: Value) -> Request<Body> {
    Request::post(uri).header("content-type", "application/json").body(Body::from(body.to_string())).unwrap()
}

#[tokio::test]
async fn an_upload_is_stored_and_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(dir.path());
    let off = kac_core::io::write::off(&kac_core::geometry::generate::icosphere(1));
    let (status, shape) = call(&app, Request::post("/v1/shapes?format=off").body(Body::from(off)).unwrap()).await;
    assert_eq!(status, StatusCode::CREATED, "{shape}");
    let id = shape["id"].as_str().unwrap();
    let (status, got) = call(&app, Request::get(format!("/v1/shapes/{id}")).body(Body::empty()).unwrap()).await;
    assert_eq!((status, got["summary"]["vertices"].as_u64()), (StatusCode::OK, Some(42)));
}

#[tokio::test]
async fn a_misspelt_option_is_refused_with_its_suggestion() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(dir.path());
    let body = json!({ "shape_id": "x", "analysis": "shape-dna", "options": { "normalisation": "area" } });
    let (status, p) = call(&app, post_json("/v1/jobs", body)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(
        (p["pointer"].as_str(), p["suggestion"].as_str()),
        (Some("/options/normalisation"), Some("normalization"))
    );
}

#[tokio::test]
async fn search_wants_one_query_and_unknown_shapes_are_not_found() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(dir.path());
    let (status, p) = call(&app, post_json("/v1/search", json!({ "k": 5 }))).await;
    assert_eq!((status, p["code"].as_str()), (StatusCode::BAD_REQUEST, Some("invalid-request")));
    let (status, p) = call(&app, post_json("/v1/search", json!({ "shape_id": "00", "k": 5 }))).await;
    assert_eq!((status, p["code"].as_str()), (StatusCode::NOT_FOUND, Some("not-found")));
    let (status, p) = call(&app, post_json("/v1/search", json!({ "fingerprint": [1.0, 2.0], "k": 2 }))).await;
    assert_eq!((status, p["searched"].as_u64()), (StatusCode::OK, Some(0)), "an empty store: {p}");
}
