// Reads one tile of a Sylva Cesium terrain layer with CesiumJS's own
// terrain provider and decoder, as a Cesium viewer would, and prints JSON:
// whether the provider has the tile, which children it says exist, the
// heights Cesium gives at the tile's 65 × 65 sample points (row 0 north),
// and the water mask it takes from the tile.
//
// node terrain.mjs LAYER_URL ZOOM X Y   (Y counted from the south, as in the URLs)
import { CesiumTerrainProvider } from "@cesium/engine";

const [url, ...numbers] = process.argv.slice(2);
const [level, x, tmsY] = numbers.map(Number);
const provider = await CesiumTerrainProvider.fromUrl(url);
// Cesium's own tile coordinates count rows from the north.
const y = provider.tilingScheme.getNumberOfYTilesAtLevel(level) - 1 - tmsY;
const available = provider.getTileDataAvailable(x, y, level);
const data = await provider.requestTileGeometry(x, y, level);
const rect = provider.tilingScheme.tileXYToRectangle(x, y, level);
const n = 65;
const heights = [];
for (let j = 0; j < n; j++) {
  for (let i = 0; i < n; i++) {
    const lon = rect.west + (i * rect.width) / (n - 1);
    const lat = rect.north - (j * rect.height) / (n - 1);
    heights.push(data.interpolateHeight(rect, lon, lat));
  }
}
// Children in Cesium's coordinates: south-west, south-east, north-west, north-east.
const quarters = [[0, 1], [1, 1], [0, 0], [1, 0]];
const children = quarters.map(([dx, dy]) => data.isChildAvailable(x, y, 2 * x + dx, 2 * y + dy));
const water = Array.from(data.waterMask);
console.log(JSON.stringify({ available, children, heights, water }));
