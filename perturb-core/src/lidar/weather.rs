//! Weather family (L-A): snow, rain, fog and sunlight, physics-based and lightweight.
