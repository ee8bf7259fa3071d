//! Placing text labels on a figure without overlaps: each label tries positions around its
//! anchor, nearest first, and takes the first that stays inside the figure and clear of every
//! label and marker already placed.

/// A rectangle in pixels (x, y of the top-left corner, width, height).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    /// Left.
    pub x: f64,
    /// Top.
    pub y: f64,
    /// Width.
    pub w: f64,
    /// Height.
    pub h: f64,
}

impl Rect {
    /// A rectangle of size (w, h) centred on (cx, cy).
    pub fn centred(cx: f64, cy: f64, w: f64, h: f64) -> Rect {
        Rect {
            x: cx - w / 2.0,
            y: cy - h / 2.0,
            w,
            h,
        }
    }

    /// True when the two overlap (touching edges do not).
    pub fn overlaps(&self, o: &Rect) -> bool {
        self.x < o.x + o.w && o.x < self.x + self.w && self.y < o.y + o.h && o.y < self.y + self.h
    }

    /// True when `self` lies inside `o`.
    pub fn inside(&self, o: &Rect) -> bool {
        self.x >= o.x
            && self.y >= o.y
            && self.x + self.w <= o.x + o.w
            && self.y + self.h <= o.y + o.h
    }

    /// The centre.
    pub fn centre(&self) -> (f64, f64) {
        (self.x + self.w / 2.0, self.y + self.h / 2.0)
    }
}

/// The width in pixels of `text` at `size` px in a sans-serif font, a generous estimate (the
/// viewer's font decides; labels get room for wide glyphs).
pub fn text_width(text: &str, size: f64) -> f64 {
    text.chars()
        .map(|c| match c {
            'i' | 'l' | 'j' | '.' | ',' | ':' | '\'' | '|' | '!' => 0.32,
            'm' | 'w' | 'M' | 'W' => 0.92,
            c if c.is_ascii_uppercase() || c.is_ascii_digit() => 0.68,
            _ => 0.6,
        })
        .sum::<f64>()
        * size
}

/// Places labels one by one, each clear of what was placed before.
#[derive(Clone, Debug)]
pub struct LabelPlacer {
    bounds: Rect,
    taken: Vec<Rect>,
}

impl LabelPlacer {
    /// A placer for labels inside `bounds`.
    pub fn new(bounds: Rect) -> Self {
        LabelPlacer {
            bounds,
            taken: Vec::new(),
        }
    }

    /// Marks a region (a marker, another label) that labels must not cover.
    pub fn block(&mut self, r: Rect) {
        self.taken.push(r);
    }

    /// What is taken so far.
    pub fn taken(&self) -> &[Rect] {
        &self.taken
    }

    /// A place for a `w` x `h` label near (ax, ay), at least `gap` pixels from it: positions
    /// in eight directions at growing distances, the first one inside the bounds and clear of
    /// everything taken; None when there is none (the label is then left out, never drawn over
    /// another). The place is taken.
    pub fn place(&mut self, ax: f64, ay: f64, w: f64, h: f64, gap: f64) -> Option<Rect> {
        const DIRS: [(f64, f64); 8] = [
            (1.0, -1.0),
            (1.0, 1.0),
            (-1.0, -1.0),
            (-1.0, 1.0),
            (0.0, -1.0),
            (1.0, 0.0),
            (0.0, 1.0),
            (-1.0, 0.0),
        ];
        for step in 0..12 {
            let d = gap + step as f64 * (h * 0.8);
            for (dx, dy) in DIRS {
                // The rectangle's nearest point lies `d` from the anchor in this direction.
                let cx = ax + dx * (d + w / 2.0 * dx.abs());
                let cy = ay + dy * (d + h / 2.0 * dy.abs());
                let r = Rect::centred(cx, cy, w, h);
                if r.inside(&self.bounds) && !self.taken.iter().any(|t| t.overlaps(&r)) {
                    self.taken.push(r);
                    return Some(r);
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_at_one_anchor_do_not_overlap_each_other_or_markers() {
        let mut p = LabelPlacer::new(Rect {
            x: 0.0,
            y: 0.0,
            w: 400.0,
            h: 300.0,
        });
        let marker = Rect::centred(200.0, 150.0, 14.0, 14.0);
        p.block(marker);
        let mut placed = Vec::new();
        for _ in 0..10 {
            placed.push(p.place(200.0, 150.0, 30.0, 16.0, 8.0).unwrap());
        }
        for (i, a) in placed.iter().enumerate() {
            assert!(!a.overlaps(&marker));
            for b in &placed[i + 1..] {
                assert!(!a.overlaps(b), "{a:?} {b:?}");
            }
        }
        // Near a corner the labels stay inside.
        let r = p.place(2.0, 2.0, 30.0, 16.0, 8.0).unwrap();
        assert!(r.x >= 0.0 && r.y >= 0.0);
    }
}
