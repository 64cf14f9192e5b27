//! The interactive HTML page of one scene's diff: one file, no server, no
//! network. The pictures are the PNGs written beside it; the per-pixel
//! values shown on hover (both colours in 8-bit and linear, the
//! visibility class, both primitive ids with their object and material,
//! both depths) are embedded as base64 of little-endian typed arrays with
//! a small table of object and material names; the script and the style
//! are inline.
//!
//! The page offers an A/B toggle (space or `t`) and flicker (`f`), side by
//! side (`2`) and difference (`3`) views, nearest-neighbour zoom down to
//! single pixels (`+`, `-`, `0` to fit), a colour scale for every map it
//! shows, and the cluster list (`compare::clusters`): a click zooms every
//! view to the cluster's box. Opened as `index.html#selftest` (or
//! `#selftest=X,Y` to hover pixel X, Y) the script drives itself through
//! real DOM events and writes what it saw into `<pre id="selftest">` as
//! JSON, for headless browser tests; `#cluster=N` opens zoomed onto the
//! N-th listed cluster, `#view=side` or `#view=diff` in that view and
//! `#hover=X,Y` with pixel X, Y's values shown (combined with `&`: links
//! a review can quote).

use std::fmt::Write as _;

use super::maps::class_color;
use super::report::Report;
use super::{Class, Comparison};
use crate::color::{Rgb, to_srgb8};
use crate::escape::html as esc;
use crate::frame::{BACKGROUND, Frame};
use crate::tri_scene::TriScene;

/// The most pixels whose values the page embeds (about 60 bytes each).
pub const MAX_HOVER_PIXELS: u64 = 512 * 384;

/// One picture of the page: its key (`a`, `b`, `heat`, `vis`,
/// `composite`), its caption and its file beside the page.
#[derive(Clone, Debug)]
pub struct PageImage {
    /// `a`, `b`, `heat`, `vis` or `composite`.
    pub key: &'static str,
    /// Caption.
    pub caption: String,
    /// File name beside the page.
    pub file: String,
}

/// What the page shows besides the report.
#[derive(Debug)]
pub struct PageInput<'a> {
    /// The scene both sides show.
    pub scene: Option<&'a TriScene>,
    /// The comparison.
    pub cmp: &'a Comparison,
    /// Linear pixel colours of side a.
    pub a: &'a [Rgb],
    /// Linear pixel colours of side b.
    pub b: &'a [Rgb],
    /// Side a's frame, when it rendered one.
    pub frame_a: Option<&'a Frame>,
    /// Side b's frame, when it rendered one.
    pub frame_b: Option<&'a Frame>,
    /// The pictures.
    pub images: Vec<PageImage>,
}

const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Standard base64 with padding.
#[must_use]
pub fn base64(bytes: &[u8]) -> String {
    let mut o = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let v = (u32::from(c[0]) << 16)
            | (u32::from(c.get(1).copied().unwrap_or(0)) << 8)
            | u32::from(c.get(2).copied().unwrap_or(0));
        for k in 0..4 {
            if k <= c.len() {
                o.push(char::from(B64[((v >> (18 - 6 * k)) & 63) as usize]));
            } else {
                o.push('=');
            }
        }
    }
    o
}

fn b64_f32(v: impl Iterator<Item = f32>) -> String {
    base64(&v.flat_map(f32::to_le_bytes).collect::<Vec<_>>())
}

fn b64_i32(v: impl Iterator<Item = i32>) -> String {
    base64(&v.flat_map(i32::to_le_bytes).collect::<Vec<_>>())
}

fn class_index(c: Class) -> u8 {
    match c {
        Class::Agree => 0,
        Class::EdgeTie => 1,
        Class::DepthTie => 2,
        Class::NearTie => 3,
        Class::Unjudgeable => 4,
        Class::Real => 5,
    }
}

const CLASSES: [Class; 6] = [
    Class::Agree,
    Class::EdgeTie,
    Class::DepthTie,
    Class::NearTie,
    Class::Unjudgeable,
    Class::Real,
];

/// The per-pixel data as a JSON object (see the module doc).
fn pixel_data(r: &Report, p: &PageInput<'_>) -> serde_json::Value {
    use serde_json::json;
    let (w, h) = (r.width as usize, r.height as usize);
    let npx = w * h;
    let objects: Vec<[String; 2]> = p
        .scene
        .map(|s| s.objects.as_slice())
        .unwrap_or_default()
        .iter()
        .map(|o| {
            let m = p
                .scene
                .and_then(|s| s.materials.get(usize::from(o.material)))
                .map(|m| m.name.clone())
                .unwrap_or_default();
            [o.label.clone(), m]
        })
        .collect();
    let clusters: Vec<serde_json::Value> = r
        .clusters
        .list
        .iter()
        .map(|c| {
            json!([
                c.bbox.x0,
                c.bbox.y0,
                c.bbox.x1,
                c.bbox.y1,
                c.kind.name(),
                c.pixels
            ])
        })
        .collect();
    let mut d = json!({
        "w": r.width, "h": r.height, "a": r.a, "b": r.b,
        "classes": CLASSES.iter().map(|c| c.name()).collect::<Vec<_>>(),
        "objects": objects,
        "clusters": clusters,
        "hover": false,
    });
    if (npx as u64) > MAX_HOVER_PIXELS || p.a.len() != npx || p.b.len() != npx {
        return d;
    }
    let c8 = |px: &[Rgb]| {
        base64(
            &px.iter()
                .flat_map(|c| [to_srgb8(c.r), to_srgb8(c.g), to_srgb8(c.b)])
                .collect::<Vec<_>>(),
        )
    };
    let lin = |px: &[Rgb]| b64_f32(px.iter().flat_map(|c| c.to_array()));
    // The sample shown per pixel: the most severe one, else the middle one.
    let n = p.cmp.samples.max(1) as usize;
    let sw = p.cmp.grid.0 as usize;
    let mut rep = Vec::with_capacity(npx);
    let mut err = Vec::with_capacity(npx);
    let mut cls = Vec::with_capacity(npx);
    for y in 0..h {
        for x in 0..w {
            let mut best = (y * n + n / 2) * sw + x * n + n / 2;
            let mut worst = Class::Agree;
            let mut e = f32::NEG_INFINITY;
            let mut any_nan = false;
            for sy in 0..n {
                for sx in 0..n {
                    let i = (y * n + sy) * sw + x * n + sx;
                    let c = p.cmp.classes.get(i).copied().unwrap_or(Class::Agree);
                    if c > worst {
                        worst = c;
                        best = i;
                    }
                    match p.cmp.errors.get(i) {
                        Some(v) if v.is_nan() => any_nan = true,
                        Some(&v) => e = e.max(v),
                        None => {}
                    }
                }
            }
            rep.push(best);
            cls.push(if p.cmp.classes.is_empty() {
                255
            } else {
                class_index(worst)
            });
            err.push(if e == f32::NEG_INFINITY && any_nan {
                f32::NAN
            } else {
                e.max(0.0)
            });
        }
    }
    d["hover"] = json!(true);
    d["c8a"] = json!(c8(p.a));
    d["c8b"] = json!(c8(p.b));
    d["la"] = json!(lin(p.a));
    d["lb"] = json!(lin(p.b));
    d["cls"] = json!(base64(&cls));
    d["err"] = json!(b64_f32(err.into_iter()));
    for (key, frame) in [("a", p.frame_a), ("b", p.frame_b)] {
        let Some(f) = frame else { continue };
        // Against an image the comparison is per pixel: show the frame's
        // middle sample of each pixel.
        let fs = f.samples.max(1) as usize;
        let fw = f.sample_width() as usize;
        let own: Vec<usize>;
        let rep: &[usize] = if f.id.len() == sw * p.cmp.grid.1 as usize {
            &rep
        } else {
            own = (0..npx)
                .map(|k| ((k / w) * fs + fs / 2) * fw + (k % w) * fs + fs / 2)
                .collect();
            &own
        };
        if rep.iter().any(|&i| i >= f.id.len()) {
            continue;
        }
        let id = |i: usize| f.id[i];
        d[format!("id{key}")] = json!(b64_i32(rep.iter().map(|&i| {
            let v = id(i);
            if v == BACKGROUND {
                -1
            } else {
                i32::try_from(v).unwrap_or(-2)
            }
        })));
        d[format!("ob{key}")] = json!(b64_i32(rep.iter().map(|&i| {
            let v = id(i);
            if v == BACKGROUND {
                -1
            } else {
                p.scene
                    .and_then(|s| s.object_of(v))
                    .and_then(|o| i32::try_from(o).ok())
                    .unwrap_or(-2)
            }
        })));
        d[format!("d{key}")] = json!(b64_f32(rep.iter().map(|&i| f.depth[i])));
    }
    d
}

/// The colour scale of the heat map (`maps::heat_map`'s formula).
fn heat_legend(tolerance: f64, largest: f64, frames: bool) -> String {
    let tol = tolerance.max(1e-12);
    let mut o = String::from("<div class=\"scale\">");
    if tol > 1e-7 {
        let _ = write!(
            o,
            "<div class=\"bar\"><span style=\"background:linear-gradient(to right,rgb(0,0,80),rgb(0,200,255))\"></span><span style=\"background:linear-gradient(to right,rgb(255,0,0),rgb(255,230,0))\"></span></div>\
             <div class=\"ticks\"><span style=\"left:0\">1e-7</span><span style=\"left:50%\">{:.1e} (tolerance)</span><span style=\"left:75%\">{:.1e}</span><span style=\"left:100%\">≥ {:.1e}</span></div>",
            tol,
            tol * 10.0,
            tol * 100.0
        );
    } else {
        let _ = write!(
            o,
            "<div class=\"bar\"><span style=\"background:linear-gradient(to right,rgb(255,0,0),rgb(255,230,0))\"></span></div>\
             <div class=\"ticks\"><span style=\"left:0\">&gt; {:.1e} (tolerance {})</span><span style=\"left:50%\">{:.1e}</span><span style=\"left:100%\">≥ {:.1e}</span></div>",
            tol,
            tolerance,
            tol * 10.0,
            tol * 100.0
        );
    }
    let _ = write!(
        o,
        "<div class=\"sw\"><i style=\"background:#000\"></i>equal (≤ {:.0e})</div>",
        tol.min(1e-7)
    );
    // Ties and uncompared samples exist only between two frames.
    if frames {
        o.push_str(
            "<div class=\"sw\"><i style=\"background:rgb(110,110,110)\"></i>shading tie</div>",
        );
        o.push_str("<div class=\"sw\"><i style=\"background:rgb(70,0,0)\"></i>not compared (different surfaces: see the visibility map)</div>");
    }
    let _ = write!(
        o,
        "<p class=\"note\">Largest linear channel difference per pixel, log scale; the largest here: {largest:.3e}.</p></div>"
    );
    o
}

fn vis_legend(r: &Report) -> String {
    let mut o = String::from("<div class=\"scale\">");
    let counts = r.visibility.map(|v| {
        [
            v.agree,
            v.edge_tie,
            v.depth_tie,
            v.near_tie,
            v.unjudgeable,
            v.real,
        ]
    });
    for (k, c) in CLASSES.iter().enumerate() {
        let [cr, cg, cb] = class_color(*c);
        let n = counts.map_or(0, |v| v[k]);
        let _ = write!(
            o,
            "<div class=\"sw\"><i style=\"background:rgb({cr},{cg},{cb})\"></i>{} ({n} samples)</div>",
            c.name().replace('_', " ")
        );
    }
    o.push_str("<p class=\"note\">Per pixel, the most serious class among its samples.</p></div>");
    o
}

fn cluster_rows(r: &Report) -> String {
    let mut o = String::new();
    if r.clusters.list.is_empty() {
        o.push_str("<p>No mismatching or notable pixels.</p>");
        return o;
    }
    let _ = write!(
        o,
        "<p>{} cluster(s){}. Click one to zoom to it.</p><table id=\"clusters\"><tr><th>#</th><th>kind</th><th>box (x, y)</th><th>pixels</th><th>{}</th><th>{}</th></tr>",
        r.clusters.total,
        if r.clusters.left_off > 0 {
            format!(
                ", the first {} listed, {} left off",
                r.clusters.list.len(),
                r.clusters.left_off
            )
        } else {
            String::new()
        },
        esc(&format!("A: {}", r.a)),
        esc(&format!("B: {}", r.b))
    );
    let side = |v: &[super::clusters::Involved]| {
        v.iter()
            .take(4)
            .map(|i| {
                let tris = if i.triangle_count > i.triangles.len() {
                    format!("{}… ({} ids)", join(&i.triangles), i.triangle_count)
                } else {
                    join(&i.triangles)
                };
                format!(
                    "{}{} <span class=\"ids\">{}</span>",
                    esc(&i.label),
                    if i.material.is_empty() {
                        String::new()
                    } else {
                        format!(" [{}]", esc(&i.material))
                    },
                    esc(&tris)
                )
            })
            .collect::<Vec<_>>()
            .join("<br>")
    };
    for (k, c) in r.clusters.list.iter().enumerate() {
        let _ = write!(
            o,
            "<tr class=\"cl k-{kind}\" data-box=\"{},{},{},{}\" tabindex=\"0\"><td>{}</td><td>{kind}</td><td class=\"box\">x {}–{}, y {}–{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            c.bbox.x0,
            c.bbox.y0,
            c.bbox.x1,
            c.bbox.y1,
            k + 1,
            c.bbox.x0,
            c.bbox.x1,
            c.bbox.y0,
            c.bbox.y1,
            c.pixels,
            side(&c.a),
            side(&c.b),
            kind = c.kind.name()
        );
    }
    o.push_str("</table>");
    o
}

fn join(v: &[u32]) -> String {
    v.iter().map(u32::to_string).collect::<Vec<_>>().join(" ")
}

/// The page of one scene.
#[must_use]
pub fn scene_page(r: &Report, p: &PageInput<'_>) -> String {
    let mut o = String::new();
    let _ = write!(
        o,
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>rendiff: {}</title>\n<style>{STYLE}</style>{LOAD_CHECK}</head><body>\n",
        esc(&r.scene)
    );
    let _ = writeln!(
        o,
        "<h1>{} <span class=\"{}\">{}</span></h1>",
        esc(&r.scene),
        r.verdict,
        r.verdict.to_uppercase()
    );
    let _ = writeln!(
        o,
        "<p class=\"sides\">A: <b>{}</b> · B: <b>{}</b> · {}×{} px · {} samples · max_depth {}</p>",
        esc(&r.a),
        esc(&r.b),
        r.width,
        r.height,
        r.samples,
        r.max_depth
    );
    o.push_str("<div class=\"toolbar\">view: <button data-mode=\"ab\" title=\"1\">A/B</button><button data-mode=\"side\" title=\"2\">side by side</button><button data-mode=\"diff\" title=\"3\">difference</button> \
        <button id=\"toggle\" title=\"space or t\">show B</button> <label><input type=\"checkbox\" id=\"flicker\"> flicker (f)</label> \
        · zoom <button id=\"zout\" title=\"-\">−</button><span id=\"zoomv\">1×</span><button id=\"zin\" title=\"+\">+</button><button id=\"zfit\" title=\"0\">fit</button> \
        <span class=\"keys\">keys: space/t toggle, f flicker, 1 2 3 views, + − 0 zoom</span></div>\n<div class=\"main\"><div id=\"views\">\n");
    let src = |key: &str| p.images.iter().find(|i| i.key == key);
    let mut panel = |id: &str, key: &str, modes: &str, caption: &str, legend: &str| {
        if let Some(img) = src(key) {
            let _ = writeln!(
                o,
                "<figure class=\"panel\" id=\"p-{id}\" data-modes=\"{modes}\"><figcaption id=\"cap-{id}\">{}</figcaption><div class=\"vp\"><div class=\"stack\"><img id=\"img-{id}\" src=\"{}\" alt=\"{}\" data-shown=\"{key}\"><div class=\"hl\"></div><div class=\"cur\"></div></div></div>{legend}</figure>",
                esc(caption),
                esc(&crate::escape::href(&img.file)),
                esc(caption)
            );
        }
    };
    let ca = format!("A: {}", r.a);
    let cb = format!("B: {}", r.b);
    panel("ab", "a", "ab", &ca, "");
    panel("a", "a", "side", &ca, "");
    panel("b", "b", "side", &cb, "");
    panel(
        "heat",
        "heat",
        "diff",
        "shading error (heat map)",
        &heat_legend(
            r.tolerance.shading_max,
            r.shading.max,
            r.visibility.is_some(),
        ),
    );
    if r.visibility.is_some() {
        panel("vis", "vis", "diff", "visibility classes", &vis_legend(r));
    }
    o.push_str("</div>\n<div id=\"info\" class=\"info\">Hover a pixel for its values.</div></div>\n<h2>Clusters</h2>\n");
    o.push_str(&cluster_rows(r));
    o.push_str("\n<h2>Summary</h2>\n<pre class=\"summary\">");
    // Line by line: the escape turns control characters (a newline too)
    // into U+FFFD.
    let summary: Vec<String> = r.summary().lines().map(esc).collect();
    o.push_str(&summary.join("\n"));
    o.push_str("</pre>\n");
    if let Some(c) = src("composite") {
        let _ = writeln!(
            o,
            "<details><summary>composite picture</summary><img class=\"composite\" src=\"{}\" alt=\"side by side\"></details>",
            esc(&crate::escape::href(&c.file))
        );
    }
    o.push_str(
        "<pre id=\"selftest\" hidden></pre>\n<script id=\"data\" type=\"application/json\">",
    );
    let data = serde_json::to_string(&pixel_data(r, p)).unwrap_or_else(|_| "{}".into());
    o.push_str(&data.replace("</", "<\\/"));
    o.push_str("</script>\n<script>");
    o.push_str(
        &SCRIPT.replace(
            "__SRC__",
            &serde_json::to_string(&[
                src("a").map(|i| crate::escape::href(&i.file)),
                src("b").map(|i| crate::escape::href(&i.file)),
            ])
            .unwrap_or_default(),
        ),
    );
    o.push_str("</script>\n</body></html>\n");
    o
}

/// Marks the page once loaded with how many of its images decoded
/// (`<body data-images="5/5">`), for headless checks of the report.
pub(crate) const LOAD_CHECK: &str = "<script>window.addEventListener('load',function(){var im=Array.prototype.slice.call(document.images);var ok=im.filter(function(i){return i.complete&&i.naturalWidth>0;}).length;document.body.setAttribute('data-images',ok+'/'+im.length);});</script>\n";

const STYLE: &str = "body{font-family:sans-serif;background:#1e1e22;color:#ddd;margin:1.5em;max-width:100%}\
h1{font-weight:normal;margin:0 0 .3em}h2{font-weight:normal;font-size:120%;margin:1.2em 0 .4em}.pass{color:#5c5}.fail{color:#f55}a{color:#8af}\
.sides{color:#bbb;overflow-wrap:anywhere}.toolbar{margin:.5em 0;line-height:2}.toolbar button{background:#333;color:#ddd;border:1px solid #555;padding:2px 8px;margin-right:2px;cursor:pointer}\
.toolbar button.on{background:#4a6;color:#fff}.keys{color:#888;font-size:85%;margin-left:1em}\
#views{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}figure.panel{margin:0;min-width:0}figure.panel.off{display:none}\
figcaption{font-size:90%;color:#ccc;margin-bottom:3px;overflow-wrap:anywhere}.vp{overflow:auto;border:1px solid #444;background:#000}\
.stack{position:relative}.stack img{display:block;width:100%;height:100%;image-rendering:pixelated;image-rendering:crisp-edges}\
.hl{position:absolute;border:2px solid #ff0;box-shadow:0 0 0 1px #000;display:none;pointer-events:none;box-sizing:border-box}\
.cur{position:absolute;outline:1px solid #fff;box-shadow:0 0 0 1px #000;display:none;pointer-events:none}\
.scale{font-size:80%;color:#bbb;margin-top:4px;max-width:420px}.bar{display:flex;height:12px;border:1px solid #555;margin:0 2em 0 1em}.bar span{flex:1}\
.ticks{position:relative;height:1.3em;margin:0 2em 0 1em}.ticks span{position:absolute;transform:translateX(-50%);white-space:nowrap}.ticks span:first-child{transform:none}.ticks span:last-child{transform:translateX(-100%)}.sw{display:inline-block;margin-right:10px}.sw i{display:inline-block;width:11px;height:11px;border:1px solid #666;vertical-align:middle;margin-right:3px}\
.note{margin:2px 0;color:#999}.main{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}.info{flex:1 1 280px;background:#111;padding:.5em 1em;margin-top:20px;font-family:monospace;font-size:90%;min-height:3em;overflow-wrap:anywhere}\
.info table td{padding:0 10px 0 0;border:none}table{border-collapse:collapse}td,th{padding:3px 8px;border-bottom:1px solid #333;text-align:left;vertical-align:top}\
tr.cl{cursor:pointer}tr.cl:hover,tr.cl.sel{background:#334}.k-real td:nth-child(2),.k-unjudgeable td:nth-child(2),.k-shading td:nth-child(2){color:#f66}.ids{color:#999;font-size:85%}td.box{white-space:nowrap}\
pre.summary{background:#111;padding:1em;white-space:pre-wrap;overflow-wrap:anywhere}img.composite{max-width:100%;height:auto;image-rendering:pixelated}";

/// The page's script; `__SRC__` is replaced by the JSON `[a, b]` file names.
const SCRIPT: &str = r#"(function(){
'use strict';
var D=JSON.parse(document.getElementById('data').textContent);
var SRC=__SRC__;
var W=D.w,H=D.h,zoom=1,mode='ab',shown='a',flick=null;
var ZL=[1,2,3,4,6,8,12,16,24,32,48,64,96,128];
function dec(s,T){if(!s)return null;var b=atob(s),u=new Uint8Array(b.length);for(var i=0;i<b.length;i++)u[i]=b.charCodeAt(i);return new T(u.buffer);}
var P={c8a:dec(D.c8a,Uint8Array),c8b:dec(D.c8b,Uint8Array),la:dec(D.la,Float32Array),lb:dec(D.lb,Float32Array),cls:dec(D.cls,Uint8Array),err:dec(D.err,Float32Array),
 ida:dec(D.ida,Int32Array),idb:dec(D.idb,Int32Array),oba:dec(D.oba,Int32Array),obb:dec(D.obb,Int32Array),da:dec(D.da,Float32Array),db:dec(D.db,Float32Array)};
var panels=[].slice.call(document.querySelectorAll('figure.panel'));
function $(id){return document.getElementById(id);}
function visible(){return panels.filter(function(p){return !p.classList.contains('off');});}
function avail(){var n=Math.max(1,visible().length);var vw=document.body.clientWidth-(mode==='ab'?312:0);return [Math.max(64,Math.floor((vw-12*(n-1))/n)-2),Math.max(64,Math.floor(window.innerHeight*0.7))];}
function layout(){var a=avail();panels.forEach(function(p){var vp=p.querySelector('.vp'),st=p.querySelector('.stack');st.style.width=W*zoom+'px';st.style.height=H*zoom+'px';
 vp.style.width=Math.min(W*zoom,a[0])+'px';vp.style.height=Math.min(H*zoom,a[1])+'px';});$('zoomv').textContent=zoom+'×';placeBox();}
function fitZoom(){var a=avail(),z=1;ZL.forEach(function(l){if(W*l<=a[0]&&H*l<=a[1])z=l;});return z;}
function setMode(m){mode=m;panels.forEach(function(p){p.classList.toggle('off',p.getAttribute('data-modes')!==m);});
 [].forEach.call(document.querySelectorAll('[data-mode]'),function(b){b.classList.toggle('on',b.getAttribute('data-mode')===m);});layout();}
function show(s){shown=s;var im=$('img-ab');if(!im)return;im.src=SRC[s==='a'?0:1];im.setAttribute('data-shown',s);
 $('cap-ab').textContent=(s==='a'?'A: '+D.a:'B: '+D.b);$('toggle').textContent=(s==='a'?'show B':'show A');}
function toggle(){show(shown==='a'?'b':'a');}
function setFlicker(on){$('flicker').checked=on;if(flick){clearInterval(flick);flick=null;}if(on){if(mode!=='ab')setMode('ab');flick=setInterval(toggle,500);}}
function setZoom(z,cx,cy){var vp=visible()[0]&&visible()[0].querySelector('.vp');if(cx===undefined&&vp){cx=(vp.scrollLeft+vp.clientWidth/2)/zoom;cy=(vp.scrollTop+vp.clientHeight/2)/zoom;}
 zoom=Math.max(1,Math.min(128,z));layout();visible().forEach(function(p){var v=p.querySelector('.vp');v.scrollLeft=cx*zoom-v.clientWidth/2;v.scrollTop=cy*zoom-v.clientHeight/2;});}
function step(d){var i=ZL.indexOf(zoom);if(i<0)i=0;setZoom(ZL[Math.max(0,Math.min(ZL.length-1,i+d))]);}
var box=null;
function placeBox(){panels.forEach(function(p){var h=p.querySelector('.hl');if(!box){h.style.display='none';return;}
 h.style.display='block';h.style.left=box[0]*zoom-2+'px';h.style.top=box[1]*zoom-2+'px';h.style.width=(box[2]-box[0]+1)*zoom+4+'px';h.style.height=(box[3]-box[1]+1)*zoom+4+'px';});}
function zoomTo(b){box=b;var a=avail(),bw=b[2]-b[0]+1,bh=b[3]-b[1]+1,z=1;
 ZL.forEach(function(l){if(l<=64&&(bw+2)*l<=a[0]&&(bh+2)*l<=a[1])z=l;});setZoom(z,(b[0]+b[2]+1)/2,(b[1]+b[3]+1)/2);placeBox();}
function fmt(v){return (v===undefined||v===null||isNaN(v))?'–':(!isFinite(v)?'∞':(Math.abs(v)>=1e-3||v===0?v.toFixed(6).replace(/0+$/,'').replace(/\.$/,''):v.toExponential(3)));}
function side(k,i){var c8=P['c8'+k],l=P['l'+k],id=P['id'+k],ob=P['ob'+k],d=P['d'+k];var r={};
 if(c8)r.rgb8=[c8[3*i],c8[3*i+1],c8[3*i+2]].join(', ');if(l)r.linear=[l[3*i],l[3*i+1],l[3*i+2]].map(fmt).join(', ');
 if(id){var t=id[i],o=ob[i];r.id=t<0?'background':String(t);r.object=o>=0&&D.objects[o]?D.objects[o][0]:(t<0?'background':'?');r.material=o>=0&&D.objects[o]?D.objects[o][1]:'';r.depth=fmt(d[i]);}
 return r;}
var hover=null;
function info(x,y){if(!D.hover){$('info').textContent='pixel '+x+', '+y+' (values not embedded: the image is larger than the page embeds)';return;}
 var i=y*W+x,a=side('a',i),b=side('b',i);var c=P.cls[i];
 hover={x:x,y:y,'class':c===255?'n/a (image)':D.classes[c],error:fmt(P.err[i]),a:a,b:b};
 var rows=[['pixel',x+', '+y,''],['class',hover['class'],''],['shading error',hover.error,'']];
 ['rgb8','linear','id','object','material','depth'].forEach(function(k){if(a[k]!==undefined||b[k]!==undefined)rows.push([k,a[k]===undefined?'–':a[k],b[k]===undefined?'–':b[k]]);});
 var h='<table><tr><td></td><td>A: '+esc(D.a)+'</td><td>B: '+esc(D.b)+'</td></tr>';
 rows.forEach(function(r){h+='<tr data-k="'+r[0]+'"><td>'+r[0]+'</td><td'+(r[2]===''?' colspan="2"':'')+'>'+esc(String(r[1]))+'</td>'+(r[2]===''?'':'<td>'+esc(String(r[2]))+'</td>')+'</tr>';});
 $('info').innerHTML=h+'</table>';}
function esc(s){return s.replace(/[&<>"]/g,function(c){return {'&':'&amp;','<':'&lt;','>':'&gt;','"':'&quot;'}[c];});}
panels.forEach(function(p){var st=p.querySelector('.stack'),vp=p.querySelector('.vp');
 st.addEventListener('mousemove',function(e){var r=st.getBoundingClientRect();var x=Math.floor((e.clientX-r.left)/zoom),y=Math.floor((e.clientY-r.top)/zoom);
  if(x<0||y<0||x>=W||y>=H)return;panels.forEach(function(q){var c=q.querySelector('.cur');c.style.display='block';c.style.left=x*zoom+'px';c.style.top=y*zoom+'px';c.style.width=zoom+'px';c.style.height=zoom+'px';});info(x,y);});
 vp.addEventListener('scroll',function(){visible().forEach(function(q){var v=q.querySelector('.vp');if(v!==vp&&(v.scrollLeft!==vp.scrollLeft||v.scrollTop!==vp.scrollTop)){v.scrollLeft=vp.scrollLeft;v.scrollTop=vp.scrollTop;}});});});
[].forEach.call(document.querySelectorAll('[data-mode]'),function(b){b.addEventListener('click',function(){setFlicker(false);setMode(b.getAttribute('data-mode'));});});
$('toggle').addEventListener('click',function(){if(mode!=='ab')setMode('ab');toggle();});
$('flicker').addEventListener('change',function(){setFlicker($('flicker').checked);});
$('zin').addEventListener('click',function(){step(1);});$('zout').addEventListener('click',function(){step(-1);});$('zfit').addEventListener('click',function(){box=null;setZoom(fitZoom(),W/2,H/2);});
[].forEach.call(document.querySelectorAll('tr.cl'),function(tr){tr.addEventListener('click',function(){[].forEach.call(document.querySelectorAll('tr.cl.sel'),function(t){t.classList.remove('sel');});tr.classList.add('sel');
 zoomTo(tr.getAttribute('data-box').split(',').map(Number));window.scrollTo(0,0);});});
document.addEventListener('keydown',function(e){if(e.target&&e.target.tagName==='INPUT'&&e.key!==' ')return;var k=e.key;
 if(k===' '||k==='t'){e.preventDefault();$('toggle').click();}else if(k==='f'){setFlicker(!$('flicker').checked);}else if(k==='+'||k==='='){step(1);}else if(k==='-'){step(-1);}else if(k==='0'){$('zfit').click();}
 else if(k==='1'||k==='2'||k==='3'){var b=document.querySelector('[data-mode="'+['ab','side','diff'][+k-1]+'"]');if(b)b.click();}});
setMode('ab');zoom=fitZoom();layout();show('a');
function hoverAt(p,x,y){var st=p.querySelector('.stack'),r=st.getBoundingClientRect();
 st.dispatchEvent(new MouseEvent('mousemove',{bubbles:true,clientX:r.left+(x+0.5)*zoom,clientY:r.top+(y+0.5)*zoom}));}
function selftest(arg){var out={};try{
 out.shown_before=$('img-ab').getAttribute('data-shown');
 $('toggle').dispatchEvent(new MouseEvent('click',{bubbles:true}));
 out.shown_after_click=$('img-ab').getAttribute('data-shown');out.src_after_click=$('img-ab').getAttribute('src');out.caption_after_click=$('cap-ab').textContent;
 document.dispatchEvent(new KeyboardEvent('keydown',{key:'t',bubbles:true}));out.shown_after_key=$('img-ab').getAttribute('data-shown');
 var xy=arg?arg.split(',').map(Number):null;var cl=document.querySelector('tr.cl');
 if(!xy&&D.clusters.length){var c=D.clusters[0];xy=[c[0],c[1]];}if(!xy)xy=[0,0];
 hoverAt($('p-ab'),xy[0],xy[1]);
 var cells={};[].forEach.call(document.querySelectorAll('#info tr[data-k]'),function(tr){cells[tr.getAttribute('data-k')]=[].slice.call(tr.children,1).map(function(td){return td.textContent;});});
 out.hover={x:xy[0],y:xy[1],cells:cells};
 var guard=0;while(zoom>1&&guard++<32)$('zout').click();out.zoom_before_cluster=zoom;
 if(cl){cl.dispatchEvent(new MouseEvent('click',{bubbles:true}));var vp=$('p-ab').querySelector('.vp'),hl=$('p-ab').querySelector('.hl');
  out.cluster={box:cl.getAttribute('data-box').split(',').map(Number),zoom:zoom,visible:[vp.scrollLeft/zoom,vp.scrollTop/zoom,(vp.scrollLeft+vp.clientWidth)/zoom,(vp.scrollTop+vp.clientHeight)/zoom],
   avail:avail(),highlight:hl.style.display,hl:[hl.style.left,hl.style.top,hl.style.width,hl.style.height].map(function(v){return parseFloat(v);})};}
 $('zin').click();out.zoom_after_in=zoom;
 document.querySelector('[data-mode="side"]').click();out.side_panels=visible().map(function(p){return p.id;});
 document.querySelector('[data-mode="diff"]').click();out.diff_panels=visible().map(function(p){return p.id;});
 out.legends=[].slice.call(document.querySelectorAll('figure.panel .scale')).length;
 }catch(e){out.error=String(e);}
 var pre=$('selftest');pre.textContent=JSON.stringify(out);pre.hidden=false;}
var m=/^#selftest(?:=(\d+,\d+))?$/.exec(location.hash);if(m)selftest(m[1]);
else{var q=new URLSearchParams(location.hash.slice(1)),vw=q.get('view'),cn=q.get('cluster');if(vw){var vb=document.querySelector('[data-mode="'+vw+'"]');if(vb)vb.click();}
 if(cn){var row=document.querySelectorAll('tr.cl')[+cn-1];if(row)row.click();}
 var hv=/^(\d+),(\d+)$/.exec(q.get('hover')||'');if(hv&&visible()[0])hoverAt(visible()[0],+hv[1],+hv[2]);}
})();"#;
