"""What each `_colour_steer` level binds, read from one `svg`-level `eval --method sd_live_sds`
run's reports (OUT_DIR/sd_live_sds/NNNN.json, docs/embedded/COLOUR.md): the levels are
cumulative and a run at `svg` passes through every earlier one, so its report says where each
caption's colour was already right.

    python3 scripts/embedded/colour_levels.py DIR   # DIR holds NNNN.json of colour60.txt's lines

Prints, over the captions that name a colour (the report's caption.colour):
  rerank  the kept sample's largest family is the colour (before it is recoloured);
  sample  the SVG is of the colour before its own fills are recoloured (svg_recoloured absent);
  svg     the SVG as written (its fills recoloured when they were not).
"""

import glob
import json
import os
import sys


def main():
    d = sys.argv[1]
    n = rerank = sample = 0
    for path in sorted(glob.glob(os.path.join(d, "[0-9][0-9][0-9][0-9].json"))):
        r = json.load(open(path))
        c = r.get("caption") or {}
        want = (c.get("colour") or {}).get("hue")
        if not want:
            continue
        n += 1
        chosen = (r.get("rerank") or {}).get("chosen", 0)
        fams = c.get("sample_families") or []
        rerank += chosen < len(fams) and fams[chosen] == want
        sample += "svg_recoloured" not in c
    pct = lambda k: f"{k}/{n} ({100.0 * k / max(n, 1):.1f} %)"
    print(json.dumps({"captions": n, "rerank_sample": pct(rerank), "sample_svg": pct(sample)}))


if __name__ == "__main__":
    main()
