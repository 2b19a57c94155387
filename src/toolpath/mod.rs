//! Toolpaths: a G-code lexer that keeps text spans, modal state, and the P' = P − E compensation rewrite; CSV paths too.
