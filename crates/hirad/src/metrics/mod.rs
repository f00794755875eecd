//! Image error: linear sRGB → XYZ → CIELUV, RMS ΔE*uv against a reference (`experiments.md` §3).
