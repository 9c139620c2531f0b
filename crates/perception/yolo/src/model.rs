//! What a YOLO segmentation model's outputs mean: the head layout, detected from the output
//! shapes and the model's metadata, and its class names.

use std::collections::BTreeMap;

/// How `output0` holds the candidates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// YOLOv5-seg: `[1, N, 5 + C + M]`, one row per anchor candidate: cx, cy, w, h, objectness,
    /// C class probabilities, M mask coefficients. Score = objectness × class probability.
    V5,
    /// Ultralytics YOLOv8/11-seg (anchor-free): `[1, 4 + C + M, N]`, one column per
    /// candidate: cx, cy, w, h, C class probabilities, M coefficients. Score = probability.
    V8,
}

impl Layout {
    /// Rows before the class probabilities.
    pub fn box_fields(self) -> usize {
        match self {
            Self::V5 => 5,
            Self::V8 => 4,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::V5 => "yolov5-seg",
            Self::V8 => "yolov8-seg",
        }
    }
}

/// A model's output geometry and classes, checked against each other.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelInfo {
    pub layout: Layout,
    /// Network input, `(width, height)`.
    pub input: (usize, usize),
    /// Class names; the index is the class id.
    pub names: Vec<String>,
    /// Candidates per image (N).
    pub candidates: usize,
    /// Mask coefficients per candidate and prototype masks (M, 32 for YOLO).
    pub mask_dim: usize,
    /// Prototype mask size, `(width, height)` (a quarter of the input for YOLO).
    pub protos: (usize, usize),
}

impl ModelInfo {
    /// Classes per candidate.
    pub fn classes(&self) -> usize {
        self.names.len()
    }

    /// Interprets the shapes of the two outputs (detections `[1, ·, ·]`, prototypes
    /// `[1, M, H', W']`) for an input of `input = (W, H)`, with the model's metadata
    /// (`layout`, `names`). The message of an error says what does not fit.
    pub fn from_shapes(
        input: (usize, usize),
        detections: &[usize],
        protos: &[usize],
        metadata: &BTreeMap<String, String>,
    ) -> Result<Self, String> {
        let (&[b0, d1, d2], &[b1, nm, ph, pw]) = (detections, protos) else {
            return Err(format!(
                "expected a detection output [1, rows, columns] and a prototype output \
                 [1, M, H/4, W/4], got {detections:?} and {protos:?}"
            ));
        };
        if b0 != 1 || b1 != 1 {
            return Err(format!(
                "expected batch 1, got outputs {detections:?} and {protos:?}"
            ));
        }
        if nm == 0 || ph == 0 || pw == 0 {
            return Err(format!("empty prototype output {protos:?}"));
        }
        let layout = match metadata.get("layout").map(String::as_str) {
            Some("yolov5-seg") => Layout::V5,
            Some("yolov8-seg" | "yolo11-seg" | "ultralytics") => Layout::V8,
            Some(other) => {
                return Err(format!(
                    "metadata layout = {other:?} is not a known head layout (yolov5-seg, \
                     yolov8-seg)"
                ));
            }
            // Ultralytics exports carry no layout key. Candidates far outnumber the fields of
            // one candidate, so the longer axis is the candidates'.
            None if d1 < d2 => Layout::V8,
            None => Layout::V5,
        };
        let (fields, candidates) = match layout {
            Layout::V5 => (d2, d1),
            Layout::V8 => (d1, d2),
        };
        let fixed = layout.box_fields() + nm;
        if fields <= fixed || candidates == 0 {
            return Err(format!(
                "{} detection output {detections:?} has {fields} fields per candidate: \
                 not enough for {} box fields, a class and {nm} mask coefficients (the \
                 prototype output has {nm} masks)",
                layout.name(),
                layout.box_fields()
            ));
        }
        let classes = fields - fixed;
        let names = match metadata.get("names") {
            Some(text) => {
                let names = parse_names(text).map_err(|e| format!("metadata names: {e}"))?;
                if names.len() != classes {
                    return Err(format!(
                        "metadata names lists {} classes, but the {} detection output \
                         {detections:?} has {fields} fields = {} box fields + {classes} \
                         classes + {nm} mask coefficients",
                        names.len(),
                        layout.name(),
                        layout.box_fields()
                    ));
                }
                names
            }
            None => (0..classes).map(|c| format!("class{c}")).collect(),
        };
        Ok(Self {
            layout,
            input,
            names,
            candidates,
            mask_dim: nm,
            protos: (pw, ph),
        })
    }
}

/// Class names from a model's `names` metadata: the Python dict repr YOLO exports write
/// (`{0: 'person', 1: 'bicycle'}`), a JSON object with integer keys, or a list. Ids must be
/// `0..n`, each once.
pub fn parse_names(text: &str) -> Result<Vec<String>, String> {
    let mut p = Parser {
        chars: text.char_indices().peekable(),
        text,
    };
    p.skip_space();
    let mut by_id: BTreeMap<usize, String> = BTreeMap::new();
    match p.next() {
        Some('{') => loop {
            p.skip_space();
            if p.eat('}') {
                break;
            }
            let key = if p.peek().is_some_and(|c| c == '\'' || c == '"') {
                let s = p.string()?;
                s.parse::<usize>()
                    .map_err(|_| format!("key {s:?} is not a class id"))?
            } else {
                p.integer()?
            };
            p.skip_space();
            p.expect(':')?;
            p.skip_space();
            let name = p.string()?;
            if by_id.insert(key, name).is_some() {
                return Err(format!("class id {key} appears twice"));
            }
            p.skip_space();
            if !p.eat(',') {
                p.skip_space();
                p.expect('}')?;
                break;
            }
        },
        Some('[') => loop {
            p.skip_space();
            if p.eat(']') {
                break;
            }
            let name = p.string()?;
            by_id.insert(by_id.len(), name);
            p.skip_space();
            if !p.eat(',') {
                p.skip_space();
                p.expect(']')?;
                break;
            }
        },
        _ => {
            return Err(format!(
                "expected {{id: 'name', ...}} or a list, got {text:?}"
            ));
        }
    }
    p.skip_space();
    if let Some(c) = p.next() {
        return Err(format!("unexpected {c:?} after the names"));
    }
    if by_id.is_empty() {
        return Err("no class names".into());
    }
    if let Some((i, (&id, _))) = by_id.iter().enumerate().find(|(i, (id, _))| *i != **id) {
        let missing = if id > i { i } else { id };
        return Err(format!(
            "class ids are not 0..{}: {missing} is missing",
            by_id.len()
        ));
    }
    Ok(by_id.into_values().collect())
}

/// Just enough of a Python-literal reader for a dict of ints to strings.
struct Parser<'a> {
    chars: std::iter::Peekable<std::str::CharIndices<'a>>,
    text: &'a str,
}

impl Parser<'_> {
    fn next(&mut self) -> Option<char> {
        self.chars.next().map(|(_, c)| c)
    }

    fn peek(&mut self) -> Option<char> {
        self.chars.peek().map(|&(_, c)| c)
    }

    fn eat(&mut self, c: char) -> bool {
        let hit = self.peek() == Some(c);
        if hit {
            self.next();
        }
        hit
    }

    fn expect(&mut self, c: char) -> Result<(), String> {
        match self.next() {
            Some(got) if got == c => Ok(()),
            got => Err(format!("expected {c:?}, got {got:?} in {:?}", self.text)),
        }
    }

    fn skip_space(&mut self) {
        while self.peek().is_some_and(char::is_whitespace) {
            self.next();
        }
    }

    fn integer(&mut self) -> Result<usize, String> {
        let mut digits = String::new();
        while let Some(c) = self.peek().filter(char::is_ascii_digit) {
            digits.push(c);
            self.next();
        }
        digits
            .parse()
            .map_err(|_| format!("expected a class id in {:?}", self.text))
    }

    /// A quoted string, `'...'` or `"..."`, with backslash escapes of the quote and backslash.
    fn string(&mut self) -> Result<String, String> {
        let quote = match self.next() {
            Some(q @ ('\'' | '"')) => q,
            got => {
                return Err(format!(
                    "expected a quoted name, got {got:?} in {:?}",
                    self.text
                ));
            }
        };
        let mut out = String::new();
        loop {
            match self.next() {
                None => return Err(format!("unterminated name in {:?}", self.text)),
                Some(c) if c == quote => return Ok(out),
                Some('\\') => match self.next() {
                    Some('n') => out.push('\n'),
                    Some('t') => out.push('\t'),
                    Some(c) => out.push(c),
                    None => return Err(format!("unterminated name in {:?}", self.text)),
                },
                Some(c) => out.push(c),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn names_in_every_spelling() {
        let want = vec!["person".to_string(), "dining table".into(), "it's".into()];
        for text in [
            r#"{0: 'person', 1: 'dining table', 2: "it's"}"#,
            r#"{"0": "person", "1": "dining table", "2": "it's"}"#,
            r#"['person', 'dining table', 'it\'s']"#,
            "{1: 'dining table', 0: 'person', 2: \"it's\",}",
        ] {
            assert_eq!(parse_names(text).unwrap(), want, "{text}");
        }
    }

    #[test]
    fn names_errors_say_what_is_wrong() {
        for (text, says) in [
            ("{0: 'a', 2: 'c'}", "1 is missing"),
            ("{1: 'a'}", "0 is missing"),
            ("{0: 'a', 0: 'b'}", "twice"),
            ("{0: 'a'", "expected"),
            ("{0: 'a} ", "unterminated"),
            ("person", "expected"),
            ("{}", "no class names"),
            ("{0: 'a'} x", "unexpected"),
        ] {
            let e = parse_names(text).unwrap_err();
            assert!(e.contains(says), "{text}: {e}");
        }
    }

    #[test]
    fn layouts_from_shapes_and_metadata() {
        let names = meta(&[("names", "{0: 'a', 1: 'b', 2: 'c'}")]);
        // YOLOv8 at 128×160: 420 candidates, 4 + 3 + 32 fields.
        let v8 =
            ModelInfo::from_shapes((160, 128), &[1, 39, 420], &[1, 32, 32, 40], &names).unwrap();
        assert_eq!(
            (v8.layout, v8.candidates, v8.classes()),
            (Layout::V8, 420, 3)
        );
        assert_eq!((v8.mask_dim, v8.protos), (32, (40, 32)));
        // YOLOv5 without a layout key: the long axis is the candidates'.
        let v5 =
            ModelInfo::from_shapes((160, 128), &[1, 1260, 40], &[1, 32, 32, 40], &names).unwrap();
        assert_eq!(
            (v5.layout, v5.candidates, v5.classes()),
            (Layout::V5, 1260, 3)
        );
        // The key decides when present.
        let mut keyed = names.clone();
        keyed.insert("layout".into(), "yolov5-seg".into());
        let v5 =
            ModelInfo::from_shapes((160, 128), &[1, 1260, 40], &[1, 32, 32, 40], &keyed).unwrap();
        assert_eq!(v5.layout, Layout::V5);
        // Without names the classes are counted from the shape.
        let bare =
            ModelInfo::from_shapes((640, 640), &[1, 116, 8400], &[1, 32, 160, 160], &meta(&[]))
                .unwrap();
        assert_eq!((bare.classes(), bare.names[79].as_str()), (80, "class79"));
    }

    #[test]
    fn shapes_that_do_not_fit_are_explained() {
        let names = meta(&[("names", "{0: 'a', 1: 'b'}")]);
        type Case<'a> = (
            &'a [usize],
            &'a [usize],
            &'a BTreeMap<String, String>,
            &'a str,
        );
        let cases: [Case; 5] = [
            (&[1, 39, 420], &[1, 32, 32, 40], &names, "lists 2 classes"),
            (
                &[1, 3, 128, 160],
                &[1, 32, 32, 40],
                &names,
                "expected a detection output",
            ),
            (&[2, 39, 420], &[2, 32, 32, 40], &names, "batch 1"),
            (&[1, 30, 420], &[1, 32, 32, 40], &names, "not enough"),
            (
                &[1, 1260, 40],
                &[1, 32, 32, 40],
                &meta(&[("layout", "yolov9-det")]),
                "yolov9-det",
            ),
        ];
        for (det, proto, metadata, says) in cases {
            let e = ModelInfo::from_shapes((160, 128), det, proto, metadata).unwrap_err();
            assert!(e.contains(says), "{det:?}: {e}");
        }
    }
}
