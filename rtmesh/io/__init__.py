"""Images in and out: OpenImageIO reading and atomic writing, the output-pass registry and its EXR channel names, tone mapping and sRGB."""
