// The tile being drawn, at its dynamic offset in the tiles' buffer: the
// hull and plain pipelines and the splats' (common.wgsl declares Tile).
@group(1) @binding(0) var<uniform> tile: Tile;
