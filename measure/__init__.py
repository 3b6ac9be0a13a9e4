"""measure: HDR beam-profile images in, medium parameter tables out."""
