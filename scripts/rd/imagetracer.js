#!/usr/bin/env node
// The imagetracerjs peer of `vectorfusion bench vectorize --rd`: traces one PNG into an SVG.
//
//   NODE_PATH=DIR/node_modules node scripts/rd/imagetracer.js IN.png OUT.svg [OPTIONS_JSON]
//
// DIR holds the npm packages `imagetracerjs` and `pngjs` (scripts/prepare_rd_set.sh installs
// them into OUT_DIR/_tools). OPTIONS_JSON is an imagetracerjs options object, e.g.
// '{"numberofcolors":8}'; a "preset" key names one of its option presets, the other keys
// override it. An "over_white": true key composites the image over white before tracing
// (imagetracerjs quantises RGBA, so transparent pixels otherwise become their own layers).
// Math.random is replaced by a seeded generator so runs are repeatable. Prints one JSON line
// on stdout: {"seconds": tracing time without node's start-up and file I/O, "bytes": N}.
'use strict';
const fs = require('fs');
const { PNG } = require('pngjs');
const ImageTracer = require('imagetracerjs');

function main() {
  const [input, output, json] = process.argv.slice(2);
  if (!input || !output) {
    console.error('usage: imagetracer.js IN.png OUT.svg [OPTIONS_JSON]');
    process.exit(2);
  }
  let options = json ? JSON.parse(json) : {};
  const overWhite = options.over_white === true;
  delete options.over_white;
  if (options.preset) {
    const base = ImageTracer.optionpresets[options.preset];
    if (!base) {
      console.error(`unknown imagetracerjs preset ${options.preset}`);
      process.exit(2);
    }
    const rest = Object.assign({}, options);
    delete rest.preset;
    options = Object.assign({}, base, rest);
  }
  let seed = 12345;
  Math.random = () => {
    // mulberry32
    seed = (seed + 0x6d2b79f5) | 0;
    let t = Math.imul(seed ^ (seed >>> 15), 1 | seed);
    t = (t + Math.imul(t ^ (t >>> 7), 61 | t)) ^ t;
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
  const png = PNG.sync.read(fs.readFileSync(input));
  const data = new Uint8ClampedArray(png.data);
  if (overWhite) {
    for (let i = 0; i < data.length; i += 4) {
      const a = data[i + 3] / 255;
      for (let c = 0; c < 3; c++) data[i + c] = Math.round(data[i + c] * a + 255 * (1 - a));
      data[i + 3] = 255;
    }
  }
  const t0 = process.hrtime.bigint();
  const svg = ImageTracer.imagedataToSVG({ width: png.width, height: png.height, data }, options);
  const seconds = Number(process.hrtime.bigint() - t0) / 1e9;
  fs.writeFileSync(output, svg);
  console.log(JSON.stringify({ seconds, bytes: Buffer.byteLength(svg) }));
}

main();
