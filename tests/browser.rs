//! The viewer in a real browser: Debian's chromium (headless, software WebGL) driven through chromedriver over
//! WebDriver, against a real `kac serve` on loopback. A shared mesh is uploaded through the page's file input, a
//! spectrum is run from the form, eigenfunctions are switched with the slider, a vertex is picked with a click and
//! its geodesic distance shown; the screenshots must show the mesh and change with what is shown, the plots must be
//! drawn, and the page must log no error and show no problem. Screenshots of each step go to `target/browser/`.

use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::{json, Value};
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Process(Child);

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn serve(dir: &std::path::Path) -> (Process, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_kac"))
        .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
        .arg(dir)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
    let v: Value = serde_json::from_str(&line).unwrap();
    let base = format!("http://{}", v["listening"].as_str().unwrap());
    (Process(child), base)
}

async fn browser() -> (Process, Client) {
    let port = free_port();
    let driver = Command::new("chromedriver")
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromedriver (Debian's chromium-driver: scripts/test-all.sh installs it)");
    let driver = Process(driver);
    let caps = json!({
        "goog:chromeOptions": {
            "binary": "/usr/bin/chromium",
            "args": ["--headless=new", "--no-sandbox", "--window-size=1400,900", "--use-angle=swiftshader",
                     "--enable-unsafe-swiftshader", "--disable-dev-shm-usage"],
        }
    });
    let connector = hyper_util::client::legacy::connect::HttpConnector::new();
    let t = Instant::now();
    loop {
        let mut b = ClientBuilder::new(connector.clone());
        b.capabilities(caps.as_object().unwrap().clone());
        match b.connect(&format!("http://127.0.0.1:{port}")).await {
            Ok(c) => return (driver, c),
            Err(e) if t.elapsed() < Duration::from_secs(20) => {
                let _ = e;
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
            Err(e) => panic!("cannot start a browser session: {e}"),
        }
    }
}

fn shots() -> PathBuf {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/browser");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The canvas as RGB pixels (its screenshot, saved as `NAME.png`).
async fn canvas(c: &Client, name: &str) -> Vec<[u8; 3]> {
    canvas_by_id(c, "canvas", name).await
}

/// A canvas by its element id as RGB pixels (its screenshot, saved as `NAME.png`).
async fn canvas_by_id(c: &Client, id: &str, name: &str) -> Vec<[u8; 3]> {
    let png_bytes = c.find(Locator::Id(id)).await.unwrap().screenshot().await.unwrap();
    std::fs::write(shots().join(format!("{name}.png")), &png_bytes).unwrap();
    let decoder = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    buf[..info.buffer_size()].chunks(channels).map(|p| [p[0], p[1], p[2]]).collect()
}

/// Pixels that are not the white background.
fn drawn(pixels: &[[u8; 3]]) -> usize {
    pixels.iter().filter(|p| p.iter().any(|&c| c < 240)).count()
}

/// Drawn pixels whose colour differs clearly between two screenshots.
fn changed(a: &[[u8; 3]], b: &[[u8; 3]]) -> usize {
    a.iter()
        .zip(b)
        .filter(|(x, y)| x.iter().zip(y.iter()).map(|(p, q)| p.abs_diff(*q) as u32).sum::<u32>() > 30)
        .count()
}

async fn js(c: &Client, script: &str) -> Value {
    c.execute(script, vec![]).await.unwrap()
}

/// Waits until `condition` (a JavaScript expression) is true; fails with the page's error box and the state.
async fn until(c: &Client, condition: &str, what: &str) {
    let t = Instant::now();
    loop {
        if js(c, &format!("return !!({condition});")).await == json!(true) {
            return;
        }
        if t.elapsed() > Duration::from_secs(90) {
            let err = js(
                c,
                "const search = document.getElementById('search-status');
                 return document.getElementById('error').textContent + ' | ' + (search ? search.textContent : '')
                   + ' | ' + JSON.stringify(window.kac.errors)",
            )
            .await;
            panic!("timed out waiting for {what}: {err}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

async fn no_errors(c: &Client, step: &str) {
    let errors = js(c, "return window.kac.errors").await;
    assert_eq!(errors, json!([]), "{step}: the page logged errors");
    // Every request the page made (modules, API calls, arrays) succeeded.
    let failed = js(
        c,
        "return performance.getEntriesByType('resource').filter(e => e.responseStatus >= 400).map(e => e.name + ' ' + e.responseStatus)",
    )
    .await;
    assert_eq!(failed, json!([]), "{step}: failed requests");
    let shown =
        js(c, "return document.getElementById('error').hidden ? '' : document.getElementById('error').textContent")
            .await;
    assert_eq!(shown, json!(""), "{step}: the page shows a problem");
}

#[tokio::test]
#[ignore = "needs chromium, chromium-driver and the shared meshes (scripts/test-all.sh installs and runs it)"]
async fn a_new_user_uploads_a_mesh_and_sees_its_eigenfunctions_and_a_geodesic() {
    let data = std::env::var("KAC_TEST_DATA")
        .or_else(|_| std::env::var("KAC_DATA_DIR"))
        .unwrap_or_else(|_| "../shared/data".into());
    let mesh = PathBuf::from(data).join("obj/fish_low_resolution.obj").canonicalize().expect("the shared fish mesh");
    let dir = tempfile::tempdir().unwrap();
    let (_server, base) = serve(dir.path());
    let (_driver, c) = browser().await;
    c.goto(&format!("{base}/")).await.unwrap();
    until(&c, "window.kac && window.kac.ready", "the page to load").await;
    no_errors(&c, "load").await;

    // Upload through the page's file input; the shape is drawn.
    c.find(Locator::Id("file")).await.unwrap().send_keys(mesh.to_str().unwrap()).await.unwrap();
    until(&c, "window.kac.state.geometry && window.kac.viewer.frames > 0", "the uploaded shape").await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let shape = canvas(&c, "1-shape").await;
    assert!(drawn(&shape) > shape.len() / 50, "the mesh is drawn: {} of {} pixels", drawn(&shape), shape.len());
    let report = js(&c, "return document.getElementById('report').textContent").await;
    assert!(report.as_str().unwrap().contains("vertices"), "the validation report is shown: {report}");
    // The form offers what the truth table allows on a triangle mesh: every analysis applies to it.
    until(&c, "document.getElementById('report').dataset.class === 'triangle_mesh'", "the shape's class").await;
    let disabled =
        js(&c, "return [...document.getElementById('analysis').options].filter(o => o.disabled).length").await;
    assert_eq!(disabled, json!(0), "no analysis is refused on a triangle mesh");

    // A spectrum with its eigenvectors, from the form.
    js(&c, "document.getElementById('analysis').value = 'spectrum'; document.getElementById('analysis').dispatchEvent(new Event('change')); return 0").await;
    js(&c, "document.querySelector('[data-path=\"k\"]').value = '12'; return 0").await;
    c.find(Locator::Id("run")).await.unwrap().click().await.unwrap();
    until(&c, "window.kac.state.array === 'eigenvectors'", "the spectrum's eigenvectors").await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let first = canvas(&c, "2-eigenfunction-1").await;
    assert!(drawn(&first) > first.len() / 50);
    let label = js(&c, "return document.getElementById('column-value').textContent").await;
    assert!(label.as_str().unwrap().contains('λ'), "λ is shown: {label}");
    // Another eigenfunction: the colours change.
    js(&c, "const s = document.getElementById('column'); s.value = '5'; s.dispatchEvent(new Event('input')); return 0")
        .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let other = canvas(&c, "3-eigenfunction-5").await;
    assert!(changed(&first, &other) > drawn(&first) / 10, "switching eigenfunctions recolours the shape");
    // The spectrum against Weyl's law is plotted.
    let plotted = js(&c, "const p = document.getElementById('plot'); const d = p.getContext('2d').getImageData(0, 0, p.width, p.height).data; let n = 0; for (let i = 3; i < d.length; i += 4) n += d[i] > 0; return n").await;
    assert!(plotted.as_u64().unwrap() > 500, "the spectrum plot is drawn");
    no_errors(&c, "spectrum").await;

    // Pick the vertex under the middle of the canvas, then its geodesic distance.
    c.find(Locator::Id("canvas")).await.unwrap().click().await.unwrap();
    until(&c, "window.kac.state.vertex !== null", "a picked vertex").await;
    let link = js(&c, "return location.hash").await;
    assert!(link.as_str().unwrap().contains("vertex="), "the link names the vertex: {link}");
    c.find(Locator::Id("geodesic")).await.unwrap().click().await.unwrap();
    until(&c, "window.kac.state.array === 'distance'", "the geodesic distance").await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let distance = canvas(&c, "4-geodesic").await;
    assert!(changed(&other, &distance) > drawn(&other) / 10, "the distance is shown");
    no_errors(&c, "geodesic").await;
    let url = js(&c, "return location.href").await;
    // A wave from the picked vertex, played with the slider: the shape's colours move with time.
    c.find(Locator::Id("wave")).await.unwrap().click().await.unwrap();
    until(&c, "window.kac.state.array === 'wave'", "the wave").await;
    js(&c, "const s = document.getElementById('column'); s.value = '2'; s.dispatchEvent(new Event('input')); return 0")
        .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let early = canvas(&c, "5-wave-early").await;
    js(
        &c,
        "const s = document.getElementById('column'); s.value = '12'; s.dispatchEvent(new Event('input')); return 0",
    )
    .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let later = canvas(&c, "6-wave-later").await;
    assert!(changed(&early, &later) > drawn(&early) / 10, "the wave moves");
    no_errors(&c, "wave").await;

    // A second shape, then every stored shape compared: the distance matrix as a heat map, nearest neighbours.
    let sphere = kac_core::io::write::off(&kac_core::geometry::generate::icosphere(3));
    let up = format!("fetch('/v1/shapes?format=off', {{ method: 'POST', body: {} }}); return 0", json!(sphere));
    js(&c, &up).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    c.find(Locator::Id("compare")).await.unwrap().click().await.unwrap();
    until(&c, "document.getElementById('plot-title').textContent.startsWith('Shape-DNA distances')", "the comparison")
        .await;
    let matrix = js(&c, "const p = document.getElementById('plot'); const d = p.getContext('2d').getImageData(0, 0, p.width, p.height).data; let n = 0; for (let i = 3; i < d.length; i += 4) n += d[i] > 0; return n").await;
    assert!(matrix.as_u64().unwrap() > 1000, "the distance matrix is drawn");
    let near = js(&c, "return document.getElementById('summary').textContent").await;
    assert_eq!(near.as_str().unwrap().lines().count(), 2, "each shape's nearest neighbour: {near}");
    no_errors(&c, "compare").await;
    let url = url.as_str().unwrap().to_string();

    // The link reopens the view in a fresh page.
    c.goto("about:blank").await.unwrap();
    c.goto(&url).await.unwrap();
    until(&c, "window.kac && window.kac.ready && window.kac.state.array === 'distance'", "the linked view").await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let again = canvas(&c, "7-link").await;
    assert!(drawn(&again) > again.len() / 50);
    no_errors(&c, "link").await;

    // A polyline: the form disables what the truth table refuses on it, with the reason as the tooltip.
    let segment = dir.path().join("segment.json");
    let polyline = kac_core::Shape::Polyline(kac_core::geometry::generate::segment(32, 1.0));
    std::fs::write(&segment, serde_json::to_vec(&kac_core::io::write::json(&polyline)).unwrap()).unwrap();
    c.find(Locator::Id("file")).await.unwrap().send_keys(segment.to_str().unwrap()).await.unwrap();
    until(&c, "document.getElementById('report').dataset.class === 'polyline'", "the polyline's class").await;
    let geodesic = js(
        &c,
        "const o = [...document.getElementById('analysis').options].find(o => o.value === 'geodesic'); return [o.disabled, o.title]",
    )
    .await;
    assert_eq!(geodesic[0], json!(true), "geodesic is not offered on a polyline: {geodesic}");
    assert!(geodesic[1].as_str().unwrap().contains("triangle mesh"), "the reason names what works: {geodesic}");
    let offered = js(&c, "return document.getElementById('analysis').selectedOptions[0].disabled").await;
    assert_eq!(offered, json!(false), "the selected analysis applies");
    no_errors(&c, "polyline").await;
    c.close().await.unwrap();
}

/// Correspondence in the viewer: a lumpy sphere (no symmetry) and a rotated copy with its vertices shuffled are
/// stored; the user picks the copy as the target and presses Match; the copy is drawn beside the shape, coloured by
/// the shape's x coordinate carried over by the functional map (within 5 % of the range at every vertex, against the
/// true permutation); a vertex picked on either side marks its true match on the other.
#[tokio::test]
#[ignore = "needs chromium and chromium-driver (scripts/test-all.sh installs and runs it)"]
async fn two_shapes_side_by_side_show_which_point_is_which() {
    let pairs::ShuffledPair { a, b, perm, inverse } = pairs::lumpy_sphere_and_shuffled_copy();
    let dir = tempfile::tempdir().unwrap();
    let (_server, base) = serve(dir.path());
    let (_driver, c) = browser().await;
    c.goto(&format!("{base}/")).await.unwrap();
    until(&c, "window.kac && window.kac.ready", "the page to load").await;
    let mut ids = vec![];
    for m in [&a, &b] {
        let off = kac_core::io::write::off(m);
        let up = format!(
            "return fetch('/v1/shapes?format=off', {{ method: 'POST', body: {} }}).then(r => r.json()).then(s => s.id)",
            json!(off)
        );
        ids.push(js(&c, &up).await.as_str().unwrap().to_string());
    }
    // Reload so the lists hold both; choose the shape, then the copy as the target, and match.
    c.goto(&format!("{base}/#shape={}", ids[0])).await.unwrap();
    c.refresh().await.unwrap();
    until(&c, "window.kac && window.kac.ready && window.kac.viewer.frames > 0", "the shape").await;
    let set_target = format!(
        "const t = document.getElementById('target'); t.value = '{}'; t.dispatchEvent(new Event('change')); return 0",
        ids[1]
    );
    js(&c, &set_target).await;
    c.find(Locator::Id("match")).await.unwrap().click().await.unwrap();
    until(&c, "window.kac.pair && window.kac.viewer2.frames > 0 && window.kac.viewer2.values", "the pair").await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let (left, right) = (canvas(&c, "8-pair-source").await, canvas_by_id(&c, "canvas2", "8-pair-target").await);
    assert!(drawn(&left) > left.len() / 50 && drawn(&right) > right.len() / 50, "both shapes are drawn");
    no_errors(&c, "match").await;
    // The colours on the copy are the shape's x carried over: compared, per copy vertex, with the x of its true
    // match (the copy's upload row y is the shape's row perm[y]).
    let check = format!(
        "const p = window.kac.pair, g = window.kac.state.geometry, g2 = p.geometry, perm = {};
         const n = g.positions.length / 3, vals = window.kac.viewer2.values;
         let worst = 0, lo = Infinity, hi = -Infinity;
         for (let v = 0; v < n; v++) {{ lo = Math.min(lo, g.positions[3 * v]); hi = Math.max(hi, g.positions[3 * v]); }}
         g2.inputToVertex.forEach((v2, y) => {{
           const x = g.positions[3 * g.inputToVertex[perm[y]]];
           worst = Math.max(worst, Math.abs(vals[v2] - x));
         }});
         return worst / (hi - lo)",
        json!(perm)
    );
    let worst = js(&c, &check).await.as_f64().unwrap();
    assert!(worst < 0.05, "x carried over by the functional map is off by {worst} of its range somewhere");
    // Pick on the shape: the mark on the copy is the true match; then pick on the copy: the mark on the shape.
    c.find(Locator::Id("canvas")).await.unwrap().click().await.unwrap();
    until(&c, "window.kac.pair.rows && window.kac.pair.rows.source >= 0", "a picked vertex and its match").await;
    let rows = js(&c, "return window.kac.pair.rows").await;
    let (x, y) = (rows["source"].as_u64().unwrap() as usize, rows["target"].as_u64().unwrap() as usize);
    assert_eq!(y as u32, inverse[x], "source row {x} is marked at copy row {y}");
    js(&c, "window.kac.pair.rows = null; return 0").await;
    c.find(Locator::Id("canvas2")).await.unwrap().click().await.unwrap();
    until(&c, "window.kac.pair.rows && window.kac.pair.rows.target >= 0", "a vertex picked on the copy").await;
    let rows = js(&c, "return window.kac.pair.rows").await;
    let (x, y) = (rows["source"].as_u64().unwrap() as usize, rows["target"].as_u64().unwrap() as usize);
    assert_eq!(x as u32, perm[y], "copy row {y} is marked at source row {x}");
    let marked = js(&c, "return [window.kac.viewer.marker, window.kac.viewer2.marker]").await;
    assert!(marked[0].is_u64() && marked[1].is_u64(), "both sides carry a mark: {marked}");
    no_errors(&c, "pick").await;
    c.close().await.unwrap();
}

/// The search panel: three closed surfaces go in through a bulk upload, which starts each one's fingerprint job
/// (every family a search reads): an icosphere of level 3 (642 vertices), the same sphere coarser (level 2, 162
/// vertices) and an ellipsoid (level 3 stretched 3× along x), each with more vertices than the 50 eigenpairs a
/// fingerprint takes. Once the other two hold their fingerprints, the panel searches from the fine sphere by the fused
/// distance (the query's own job, if still running, is the panel's 202 to follow): both others are listed, nearest
/// first, each with a finite distance per family; choosing a row shows that shape.
#[tokio::test]
#[ignore = "needs chromium and chromium-driver (scripts/test-all.sh installs and runs it)"]
async fn the_search_panel_lists_the_nearest_shapes_with_a_distance_per_family() {
    use kac_core::geometry::generate;
    let fine = generate::icosphere(3);
    let coarse = generate::icosphere(2);
    let mut ellipsoid = generate::icosphere(3);
    for p in &mut ellipsoid.vertices {
        p[0] *= 3.0;
    }
    let dir = tempfile::tempdir().unwrap();
    let (_server, base) = serve(dir.path());
    let (_driver, c) = browser().await;
    c.goto(&format!("{base}/")).await.unwrap();
    until(&c, "window.kac && window.kac.ready", "the page to load").await;
    let files = json!([
        ["fine-sphere.off", kac_core::io::write::off(&fine)],
        ["coarse-sphere.off", kac_core::io::write::off(&coarse)],
        ["ellipsoid.off", kac_core::io::write::off(&ellipsoid)],
    ]);
    let up = format!(
        "const form = new FormData();
         for (const [name, text] of {files}) form.append('file', new Blob([text]), name);
         return fetch('/v1/shapes/bulk', {{ method: 'POST', body: form }}).then(r => r.json())"
    );
    let bulk = js(&c, &up).await;
    assert_eq!(bulk["created"], json!(3), "the three shapes are stored: {bulk}");
    assert_eq!(bulk["unstarted"], json!(0), "every fingerprint job started: {bulk}");
    let stored = bulk["files"].as_array().unwrap();
    let ids: Vec<String> = stored.iter().map(|f| f["shape"]["id"].as_str().unwrap().to_string()).collect();
    let jobs: Vec<String> = stored.iter().map(|f| f["job"]["id"].as_str().unwrap().to_string()).collect();
    // A search finds only shapes that hold a fingerprint: the neighbours' jobs end first.
    for job in &jobs[1..] {
        let t = Instant::now();
        loop {
            let status =
                js(&c, &format!("return fetch('/v1/jobs/{job}').then(r => r.json()).then(j => j.status)")).await;
            if status == json!("succeeded") {
                break;
            }
            assert!(status != json!("failed") && status != json!("canceled"), "fingerprint job {job}: {status}");
            assert!(t.elapsed() < Duration::from_secs(90), "fingerprint job {job} is still {status}");
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }

    // The viewer on the fine sphere; search by the fused distance.
    c.goto(&format!("{base}/#shape={}", ids[0])).await.unwrap();
    c.refresh().await.unwrap();
    until(&c, "window.kac && window.kac.ready && window.kac.viewer.frames > 0", "the shape").await;
    until(&c, "!document.getElementById('search-run').disabled", "the search control").await;
    js(
        &c,
        "const d = document.getElementById('search-descriptor'); d.value = 'fused';
         d.dispatchEvent(new Event('change')); document.getElementById('search-count').value = '10'; return 0",
    )
    .await;
    c.find(Locator::Id("search-run")).await.unwrap().click().await.unwrap();
    until(&c, "document.querySelectorAll('#search-table tbody tr').length === 2", "the two neighbours").await;
    let rows = js(
        &c,
        r#"return [...document.querySelectorAll('#search-table tbody tr')].map(tr => ({
             id: tr.dataset.shapeId,
             distance: Number(tr.querySelector('[data-col="distance"]').dataset.value),
             families: Object.fromEntries([...tr.querySelectorAll('[data-family]')]
               .map(td => [td.dataset.family, Number(td.textContent)])),
           }))"#,
    )
    .await;
    let rows = rows.as_array().unwrap();
    let mut listed: Vec<&str> = rows.iter().map(|r| r["id"].as_str().unwrap()).collect();
    listed.sort();
    let mut others = vec![ids[1].as_str(), ids[2].as_str()];
    others.sort();
    assert_eq!(listed, others, "the neighbours are the two other shapes (the query left out)");
    for r in rows {
        for family in ["shape-dna", "heat-distribution", "gps-d2"] {
            // NaN (a cell that is no number) comes back as null.
            let x = r["families"][family].as_f64();
            assert!(x.is_some_and(f64::is_finite), "{family} distance of {}: {}", r["id"], r["families"]);
        }
    }
    let distances: Vec<f64> = rows.iter().map(|r| r["distance"].as_f64().unwrap_or(f64::NAN)).collect();
    assert!(distances.iter().all(|d| d.is_finite()), "fused distances: {distances:?}");
    assert!(distances.windows(2).all(|w| w[0] <= w[1]), "nearest first: {distances:?}");
    let facts = js(&c, "return document.getElementById('search-facts').textContent").await;
    assert!(facts.as_str().unwrap().contains("searched"), "what was searched is shown: {facts}");
    no_errors(&c, "search").await;

    // Choosing the nearest shows it (its geometry, the shape list and the link follow).
    let first = rows[0]["id"].as_str().unwrap().to_string();
    let neighbour = stored.iter().find(|f| f["shape"]["id"] == json!(first)).unwrap();
    let vertices = neighbour["shape"]["summary"]["vertices"].clone();
    c.find(Locator::Css("#search-table tbody tr")).await.unwrap().click().await.unwrap();
    until(
        &c,
        &format!(
            "window.kac.state.shape === '{first}' && document.getElementById('shapes').value === '{first}' \
             && location.hash.includes('shape={first}')"
        ),
        "the neighbour shown",
    )
    .await;
    let shown = js(&c, "return window.kac.state.summary.vertices").await;
    assert_eq!(shown, vertices, "the viewer holds the neighbour's geometry");
    let current = js(&c, "return document.querySelector('#search-table tbody tr.current').dataset.shapeId").await;
    assert_eq!(current, json!(first), "the row of the shape shown is marked");
    no_errors(&c, "neighbour").await;
    c.close().await.unwrap();
}

#[path = "support/pairs.rs"]
mod pairs;
