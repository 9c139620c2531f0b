//! `--frames START:END[:STEP]`: a range of frame ids (inclusive).

use std::str::FromStr;

/// Frame ids `start..=end` every `step`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRange {
    pub start: u64,
    pub end: u64,
    pub step: u64,
}

impl FrameRange {
    /// Whether the frame with this dataset id is selected (ids that are not numbers never are).
    pub fn contains(&self, id: &str) -> bool {
        id.parse::<u64>().is_ok_and(|n| {
            n >= self.start && n <= self.end && (n - self.start).is_multiple_of(self.step)
        })
    }
}

impl FromStr for FrameRange {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = s.split(':').collect();
        let num = |p: &str| {
            p.trim()
                .parse::<u64>()
                .map_err(|_| format!("{p:?} is not a frame number"))
        };
        let range = match parts.as_slice() {
            [a, b] => Self {
                start: num(a)?,
                end: num(b)?,
                step: 1,
            },
            [a, b, c] => Self {
                start: num(a)?,
                end: num(b)?,
                step: num(c)?,
            },
            _ => return Err("expected START:END or START:END:STEP".into()),
        };
        if range.step == 0 || range.end < range.start {
            return Err("need START <= END and STEP >= 1".into());
        }
        Ok(range)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_selects() {
        let r: FrameRange = "10:20:4".parse().unwrap();
        assert!(
            r.contains("000010")
                && r.contains("000018")
                && !r.contains("000020")
                && !r.contains("abc")
        );
        assert!("5:1".parse::<FrameRange>().is_err());
        assert!("1:5:0".parse::<FrameRange>().is_err());
        assert!("1".parse::<FrameRange>().is_err());
        assert_eq!("0:3".parse::<FrameRange>().unwrap().step, 1);
    }
}
