//! Where the two sides disagree: the failing and notable pixels of a
//! comparison grouped into 8-connected clusters, each with its bounding
//! box, its kind, its size and the objects and triangles involved on each
//! side, for a reviewer to go to.
//!
//! A pixel's kind is the most severe among its samples
//! ([`ClusterKind`], in decreasing severity: real, unjudgeable, shading
//! over the bound, near tie, depth tie, edge tie; for a frame against an
//! image, beyond the 8-bit bound). A cluster is a connected set of pixels
//! of one kind, neighbours including the diagonal ones. Clusters are
//! sorted by severity, then by size (largest first), then by position,
//! and capped at [`MAX_CLUSTERS`]; [`Clusters::left_off`] says how many
//! more there were.

use serde::Serialize;

use super::{Class, Comparison};
use crate::color::{Rgb, to_srgb8};
use crate::frame::{BACKGROUND, Frame};
use crate::tri_scene::TriScene;

/// The most clusters a report lists.
pub const MAX_CLUSTERS: usize = 200;

/// The most triangle ids listed per object and side of a cluster.
pub const MAX_TRIANGLES_LISTED: usize = 16;

/// What a cluster's pixels show, from the most severe down.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ClusterKind {
    /// A real visibility mismatch (fails the verdict).
    Real,
    /// A tie the verdict cannot judge (fails the verdict).
    Unjudgeable,
    /// Both sides see the same triangle, shaded differently beyond the
    /// shading bound (fails the verdict).
    Shading,
    /// A frame against an image: beyond the 8-bit bound.
    #[serde(rename = "beyond_8bit")]
    Beyond8bit,
    /// A near-plane tie.
    NearTie,
    /// A depth tie.
    DepthTie,
    /// An edge tie.
    EdgeTie,
}

impl ClusterKind {
    /// The name used in reports.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            ClusterKind::Real => "real",
            ClusterKind::Unjudgeable => "unjudgeable",
            ClusterKind::Shading => "shading",
            ClusterKind::Beyond8bit => "beyond_8bit",
            ClusterKind::NearTie => "near_tie",
            ClusterKind::DepthTie => "depth_tie",
            ClusterKind::EdgeTie => "edge_tie",
        }
    }

    /// `true` for the kinds that fail a verdict.
    #[must_use]
    pub fn fails(self) -> bool {
        matches!(
            self,
            ClusterKind::Real | ClusterKind::Unjudgeable | ClusterKind::Shading
        )
    }

    /// The kind of a visibility class (`None` for agreement).
    #[must_use]
    pub fn of_class(c: Class) -> Option<ClusterKind> {
        match c {
            Class::Agree => None,
            Class::EdgeTie => Some(ClusterKind::EdgeTie),
            Class::DepthTie => Some(ClusterKind::DepthTie),
            Class::NearTie => Some(ClusterKind::NearTie),
            Class::Unjudgeable => Some(ClusterKind::Unjudgeable),
            Class::Real => Some(ClusterKind::Real),
        }
    }
}

/// A pixel rectangle, inclusive of both corners.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct PixelBox {
    /// Leftmost column.
    pub x0: u32,
    /// Top row.
    pub y0: u32,
    /// Rightmost column.
    pub x1: u32,
    /// Bottom row.
    pub y1: u32,
}

impl PixelBox {
    /// Width in pixels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.x1 - self.x0 + 1
    }

    /// Height in pixels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.y1 - self.y0 + 1
    }
}

/// One object seen on one side of a cluster.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Involved {
    /// Object index (`None`: the background).
    pub object: Option<u32>,
    /// The object's label (`objects[i] (kind)`), or "background".
    pub label: String,
    /// Its material's name.
    pub material: String,
    /// Samples of the cluster that see it.
    pub samples: u64,
    /// Distinct primitive ids seen, ascending (the first
    /// [`MAX_TRIANGLES_LISTED`]).
    pub triangles: Vec<u32>,
    /// How many distinct primitive ids there were.
    pub triangle_count: usize,
}

/// A connected group of pixels of one kind.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Cluster {
    /// What the pixels show.
    pub kind: ClusterKind,
    /// Bounding box.
    #[serde(rename = "box")]
    pub bbox: PixelBox,
    /// Pixels in the cluster.
    pub pixels: u64,
    /// Samples of those pixels of the cluster's kind.
    pub samples: u64,
    /// The objects side a sees there (empty for an image), most samples first.
    pub a: Vec<Involved>,
    /// The objects side b sees there (empty for an image), most samples first.
    pub b: Vec<Involved>,
}

/// The clusters of a comparison.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Clusters {
    /// Clusters found in all.
    pub total: usize,
    /// Clusters not listed (beyond the cap).
    pub left_off: usize,
    /// The listed clusters, most severe and largest first.
    pub list: Vec<Cluster>,
}

/// A component of equal labels: its label, bounding box and pixel indices.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Component<K> {
    /// The label shared by its pixels.
    pub label: K,
    /// Bounding box.
    pub bbox: PixelBox,
    /// Row-major pixel indices, ascending.
    pub pixels: Vec<usize>,
}

/// The 8-connected components of equal `Some` labels of a `width` ×
/// `height` grid (row-major), in order of their first pixel. Returns an
/// empty list when `labels` does not hold `width · height` entries.
#[must_use]
pub fn components<K: Copy + Eq>(
    width: u32,
    height: u32,
    labels: &[Option<K>],
) -> Vec<Component<K>> {
    let (w, h) = (width as usize, height as usize);
    if labels.len() != w * h {
        return Vec::new();
    }
    let mut seen = vec![false; labels.len()];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for start in 0..labels.len() {
        let Some(label) = labels[start] else { continue };
        if seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let mut pixels = Vec::new();
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        while let Some(i) = stack.pop() {
            pixels.push(i);
            let (x, y) = (i % w, i / w);
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
            for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    let j = ny * w + nx;
                    if !seen[j] && labels[j] == Some(label) {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        pixels.sort_unstable();
        let c = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        out.push(Component {
            label,
            bbox: PixelBox {
                x0: c(x0),
                y0: c(y0),
                x1: c(x1),
                y1: c(y1),
            },
            pixels,
        });
    }
    out
}

/// The kind of one sample of two frames (`None`: nothing to show).
fn sample_kind(cmp: &Comparison, i: usize, shading_max: f64) -> Option<ClusterKind> {
    let class = cmp.classes.get(i).copied().unwrap_or(Class::Agree);
    if class != Class::Agree {
        return ClusterKind::of_class(class);
    }
    let e = f64::from(cmp.errors.get(i).copied().unwrap_or(0.0));
    let tie = cmp.ties.get(i).copied().unwrap_or(false);
    (!tie && e > shading_max).then_some(ClusterKind::Shading)
}

/// Per pixel, the most severe kind among its samples (frames).
fn pixel_kinds(
    cmp: &Comparison,
    width: u32,
    height: u32,
    shading_max: f64,
) -> Vec<Option<ClusterKind>> {
    let n = cmp.samples.max(1) as usize;
    let sw = cmp.grid.0 as usize;
    let mut out = Vec::with_capacity(width as usize * height as usize);
    for y in 0..height as usize {
        for x in 0..width as usize {
            let mut k: Option<ClusterKind> = None;
            for b in 0..n {
                for a in 0..n {
                    let s = sample_kind(cmp, (y * n + b) * sw + x * n + a, shading_max);
                    k = match (k, s) {
                        (Some(p), Some(q)) => Some(p.min(q)),
                        (p, q) => p.or(q),
                    };
                }
            }
            out.push(k);
        }
    }
    out
}

/// Collects, per object, the samples and primitive ids a side sees.
#[derive(Default)]
struct Seen {
    by_object: std::collections::BTreeMap<Option<u32>, (u64, std::collections::BTreeSet<u32>)>,
}

impl Seen {
    fn add(&mut self, scene: &TriScene, id: u32) {
        let object = (id != BACKGROUND).then(|| scene.object_of(id)).flatten();
        let e = self.by_object.entry(object).or_default();
        e.0 += 1;
        if id != BACKGROUND {
            e.1.insert(id);
        }
    }

    fn finish(self, scene: &TriScene) -> Vec<Involved> {
        let mut v: Vec<Involved> = self
            .by_object
            .into_iter()
            .map(|(object, (samples, ids))| {
                let info = object.and_then(|o| scene.objects.get(o as usize));
                Involved {
                    object,
                    label: info.map_or_else(|| "background".to_string(), |o| o.label.clone()),
                    material: info
                        .and_then(|o| scene.materials.get(usize::from(o.material)))
                        .map(|m| m.name.clone())
                        .unwrap_or_default(),
                    samples,
                    triangle_count: ids.len(),
                    triangles: ids.into_iter().take(MAX_TRIANGLES_LISTED).collect(),
                }
            })
            .collect();
        v.sort_by(|p, q| q.samples.cmp(&p.samples).then(p.object.cmp(&q.object)));
        v
    }
}

fn sort_and_cap(mut list: Vec<Cluster>) -> Clusters {
    list.sort_by(|p, q| {
        p.kind
            .cmp(&q.kind)
            .then(q.pixels.cmp(&p.pixels))
            .then((p.bbox.y0, p.bbox.x0).cmp(&(q.bbox.y0, q.bbox.x0)))
    });
    let total = list.len();
    list.truncate(MAX_CLUSTERS);
    Clusters {
        total,
        left_off: total - list.len(),
        list,
    }
}

/// The clusters of two frames of `scene` and their comparison: samples of
/// every visibility class but agreement, and agreeing samples whose
/// shading error exceeds `shading_max` (shading ties apart). Each side
/// lists the objects it sees on the cluster's samples of its kind.
#[must_use]
pub fn of_frames(
    scene: &TriScene,
    cmp: &Comparison,
    a: &Frame,
    b: &Frame,
    shading_max: f64,
) -> Clusters {
    let (w, h) = (a.width, a.height);
    if cmp.classes.len() != a.id.len() || a.id.len() != b.id.len() {
        return Clusters::default();
    }
    let kinds = pixel_kinds(cmp, w, h, shading_max);
    let n = cmp.samples.max(1) as usize;
    let sw = cmp.grid.0 as usize;
    let list = components(w, h, &kinds)
        .into_iter()
        .map(|c| {
            let (mut sa, mut sb, mut samples) = (Seen::default(), Seen::default(), 0u64);
            for &p in &c.pixels {
                let (x, y) = (p % w as usize, p / w as usize);
                for sy in 0..n {
                    for sx in 0..n {
                        let i = (y * n + sy) * sw + x * n + sx;
                        if sample_kind(cmp, i, shading_max) == Some(c.label) {
                            samples += 1;
                            sa.add(scene, a.id[i]);
                            sb.add(scene, b.id[i]);
                        }
                    }
                }
            }
            Cluster {
                kind: c.label,
                bbox: c.bbox,
                pixels: c.pixels.len() as u64,
                samples,
                a: sa.finish(scene),
                b: sb.finish(scene),
            }
        })
        .collect();
    sort_and_cap(list)
}

/// The largest 8-bit sRGB channel difference of two linear colours.
#[must_use]
pub fn max_diff8(p: Rgb, q: Rgb) -> u8 {
    [
        to_srgb8(p.r).abs_diff(to_srgb8(q.r)),
        to_srgb8(p.g).abs_diff(to_srgb8(q.g)),
        to_srgb8(p.b).abs_diff(to_srgb8(q.b)),
    ]
    .into_iter()
    .max()
    .unwrap_or(0)
}

/// The clusters of two pictures (at least one an image): pixels whose
/// 8-bit difference exceeds `max8`. Where one side is a frame
/// (`frame`: the scene, the frame, and whether it is side a), that side
/// lists the objects its samples see there.
#[must_use]
pub fn of_images(
    width: u32,
    height: u32,
    a: &[Rgb],
    b: &[Rgb],
    max8: u8,
    frame: Option<(&TriScene, &Frame, bool)>,
) -> Clusters {
    if a.len() != b.len() {
        return Clusters::default();
    }
    let beyond: Vec<bool> = a
        .iter()
        .zip(b)
        .map(|(p, q)| max_diff8(*p, *q) > max8)
        .collect();
    of_image_mask(width, height, &beyond, frame)
}

/// The clusters of the pixels marked in `beyond` (a comparison of two
/// pictures, at least one an image: its pixels over the bound beyond the
/// images' rounding, or beyond the 8-bit bound), as [`of_images`].
#[must_use]
pub fn of_image_mask(
    width: u32,
    height: u32,
    beyond: &[bool],
    frame: Option<(&TriScene, &Frame, bool)>,
) -> Clusters {
    if beyond.len() != width as usize * height as usize {
        return Clusters::default();
    }
    let kinds: Vec<Option<ClusterKind>> = beyond
        .iter()
        .map(|&b| b.then_some(ClusterKind::Beyond8bit))
        .collect();
    let list = components(width, height, &kinds)
        .into_iter()
        .map(|c| {
            let mut seen = Seen::default();
            let mut with_frame = Vec::new();
            if let Some((scene, f, _)) = frame {
                let n = f.samples.max(1) as usize;
                let sw = f.sample_width() as usize;
                for &p in &c.pixels {
                    let (x, y) = (p % width as usize, p / width as usize);
                    for sy in 0..n {
                        for sx in 0..n {
                            if let Some(&id) = f.id.get((y * n + sy) * sw + x * n + sx) {
                                seen.add(scene, id);
                            }
                        }
                    }
                }
                with_frame = seen.finish(scene);
            }
            let on_a = frame.is_some_and(|(_, _, is_a)| is_a);
            let (ia, ib) = if on_a {
                (with_frame, Vec::new())
            } else {
                (Vec::new(), with_frame)
            };
            Cluster {
                kind: c.label,
                bbox: c.bbox,
                pixels: c.pixels.len() as u64,
                samples: c.pixels.len() as u64,
                a: ia,
                b: ib,
            }
        })
        .collect();
    sort_and_cap(list)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(rows: &[&str]) -> (u32, u32, Vec<Option<u8>>) {
        let h = u32::try_from(rows.len()).unwrap();
        let w = u32::try_from(rows[0].len()).unwrap();
        let v = rows
            .iter()
            .flat_map(|r| r.bytes().map(|c| (c != b'.').then_some(c)))
            .collect();
        (w, h, v)
    }

    #[test]
    fn two_separate_blobs_are_two_clusters_with_their_boxes_and_counts() {
        let (w, h, v) = grid(&[
            "xx......", //
            "xx......", //
            "........", //
            ".....xxx", //
            "......x.", //
        ]);
        let c = components(w, h, &v);
        assert_eq!(c.len(), 2);
        assert_eq!(
            c[0].bbox,
            PixelBox {
                x0: 0,
                y0: 0,
                x1: 1,
                y1: 1
            }
        );
        assert_eq!(c[0].pixels.len(), 4);
        assert_eq!(
            c[1].bbox,
            PixelBox {
                x0: 5,
                y0: 3,
                x1: 7,
                y1: 4
            }
        );
        assert_eq!((c[1].bbox.width(), c[1].bbox.height()), (3, 2));
        assert_eq!(c[1].pixels.len(), 4);
    }

    #[test]
    fn diagonal_neighbours_join_and_labels_do_not_mix() {
        let (w, h, v) = grid(&[
            "x...", //
            ".x..", //
            "..x.", //
            "...y", //
        ]);
        let c = components(w, h, &v);
        assert_eq!(c.len(), 2, "{c:?}");
        assert_eq!(c[0].label, b'x');
        assert_eq!(c[0].pixels, vec![0, 5, 10]);
        assert_eq!(
            c[0].bbox,
            PixelBox {
                x0: 0,
                y0: 0,
                x1: 2,
                y1: 2
            }
        );
        assert_eq!(c[1].label, b'y');
        assert_eq!(c[1].pixels, vec![15]);
    }

    #[test]
    fn a_wrong_length_gives_no_components() {
        assert!(components::<u8>(3, 3, &[None; 4]).is_empty());
    }

    #[test]
    fn images_cluster_pixels_beyond_the_bound_by_severity_then_size() {
        let (w, h) = (6u32, 4u32);
        let a = vec![Rgb::new(0.5, 0.5, 0.5); 24];
        let mut b = a.clone();
        // A single pixel, and a 2x2 block; one pixel within the bound.
        b[0] = Rgb::new(0.9, 0.5, 0.5);
        for i in [9usize, 10, 15, 16] {
            b[i] = Rgb::new(0.0, 0.5, 0.5);
        }
        b[23] = Rgb::new(0.501, 0.5, 0.5);
        let c = of_images(w, h, &a, &b, 2, None);
        assert_eq!((c.total, c.left_off), (2, 0));
        assert_eq!(c.list[0].pixels, 4);
        assert_eq!(
            c.list[0].bbox,
            PixelBox {
                x0: 3,
                y0: 1,
                x1: 4,
                y1: 2
            }
        );
        assert_eq!(c.list[1].pixels, 1);
        assert!(c.list.iter().all(|c| c.kind == ClusterKind::Beyond8bit));
    }
}
