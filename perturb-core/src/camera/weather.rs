//! Weather and illumination family (C-C): frost, snow, fog, brightness, contrast and the animated overlays (rain, raindrops, lightning, smoke, sun glare, snowflakes).
