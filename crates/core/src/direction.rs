//! The approach direction of a measured target (`+` forward, `-` reverse), shared by linear, rotary and thermal data.

/// Direction of approach to a target: `+` (forward, increasing coordinate or angle) or `-`
/// (reverse). Serialized as `"forward"`/`"reverse"`; documents that spell it `+`/`-` use
/// [`symbol`] with `#[serde(with = "crate::direction::symbol")]`.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// `+`: approached with the coordinate or angle increasing.
    Forward,
    /// `-`: approached with the coordinate or angle decreasing.
    Reverse,
}

impl Direction {
    /// The file symbol: `+` or `-`.
    pub fn symbol(self) -> &'static str {
        match self {
            Direction::Forward => "+",
            Direction::Reverse => "-",
        }
    }

    /// The word: `forward` or `reverse`.
    pub fn name(self) -> &'static str {
        match self {
            Direction::Forward => "forward",
            Direction::Reverse => "reverse",
        }
    }

    /// Parse `+`/`-` (also `up`/`down`, `forward`/`reverse`/`backward`, `fwd`/`rev`/`bwd`,
    /// `pos`/`neg`, any case).
    pub fn parse(text: &str) -> Option<Direction> {
        match text.trim().to_ascii_lowercase().as_str() {
            "+" | "up" | "forward" | "fwd" | "pos" | "positive" => Some(Direction::Forward),
            "-" | "down" | "reverse" | "rev" | "backward" | "bwd" | "neg" | "negative" => {
                Some(Direction::Reverse)
            }
            _ => None,
        }
    }

    /// Parse the symbol only: `+` or `-` (surrounding blanks ignored).
    pub fn parse_symbol(text: &str) -> Option<Direction> {
        match text.trim() {
            "+" => Some(Direction::Forward),
            "-" => Some(Direction::Reverse),
            _ => None,
        }
    }
}

impl std::fmt::Display for Direction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.symbol())
    }
}

/// Serde as `"+"`/`"-"`, for the documents (rotary analyses) that spell a direction so.
pub mod symbol {
    use super::Direction;

    /// Write a direction as `"+"` or `"-"`.
    pub fn serialize<S: serde::Serializer>(d: &Direction, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(d.symbol())
    }

    /// Read `"+"` or `"-"` (surrounding blanks ignored); anything else is an error.
    pub fn deserialize<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Direction, D::Error> {
        let text = <std::borrow::Cow<'de, str> as serde::Deserialize>::deserialize(d)?;
        Direction::parse_symbol(&text).ok_or_else(|| {
            serde::de::Error::invalid_value(serde::de::Unexpected::Str(&text), &"\"+\" or \"-\"")
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Serialize, serde::Deserialize, PartialEq, Debug)]
    struct Row {
        word: Direction,
        #[serde(with = "symbol")]
        sign: Direction,
    }

    #[test]
    fn words_and_symbols_round_trip() {
        let row = Row {
            word: Direction::Reverse,
            sign: Direction::Forward,
        };
        let json = serde_json::to_string(&row).unwrap();
        assert_eq!(json, r#"{"word":"reverse","sign":"+"}"#);
        assert_eq!(serde_json::from_str::<Row>(&json).unwrap(), row);
        let err = serde_json::from_str::<Row>(r#"{"word":"reverse","sign":"up"}"#).unwrap_err();
        assert!(err.to_string().contains("\"+\" or \"-\""), "{err}");
    }

    #[test]
    fn parsing_is_broad_for_words_and_strict_for_symbols() {
        assert_eq!(Direction::parse(" Backward "), Some(Direction::Reverse));
        assert_eq!(Direction::parse("POS"), Some(Direction::Forward));
        assert_eq!(Direction::parse("sideways"), None);
        assert_eq!(Direction::parse_symbol(" - "), Some(Direction::Reverse));
        assert_eq!(Direction::parse_symbol("up"), None);
        assert_eq!(Direction::Forward.to_string(), "+");
        assert_eq!(Direction::Reverse.name(), "reverse");
    }
}
