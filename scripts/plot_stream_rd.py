#!/usr/bin/env python3
"""Rate-distortion plot of the tele-presence stream (docs/streaming.md) as SVG, from the CSV of
scripts/stream_rd.sh; standard library only.
  python3 scripts/plot_stream_rd.py rd.csv docs/images/stream_rd.svg
Left: receiver novel-view PSNR against the sender's full-quality model; right: receiver
novel-view PSNR against the ground truth, with each sender's own PSNR dashed."""
import csv
import sys

rows = list(csv.DictReader(open(sys.argv[1])))
series = {}
for r in rows:
    series.setdefault((r["run"], r["codec"]), []).append(r)
COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b"]
W, H, PAD = 460, 330, 55


def panel(x0, key, title, sender_key=None):
    pts = [(float(r["total_kbps"]), float(r[key])) for s in series.values() for r in s if r[key]]
    if sender_key:
        pts += [(float(r["total_kbps"]), float(r[sender_key])) for s in series.values() for r in s]
    xmax = max(p[0] for p in pts) * 1.05
    ymin = min(p[1] for p in pts) - 0.3
    ymax = max(p[1] for p in pts) + 0.3
    sx = lambda x: x0 + PAD + (W - PAD - 15) * x / xmax
    sy = lambda y: H - PAD + (PAD + 25 - H) * (y - ymin) / (ymax - ymin)
    out = [f'<text x="{x0 + W / 2}" y="18" text-anchor="middle" font-size="13">{title}</text>',
           f'<rect x="{x0 + PAD}" y="25" width="{W - PAD - 15}" height="{H - PAD - 25}" '
           'fill="none" stroke="#444"/>']
    for i in range(6):
        xv = xmax * i / 5
        out.append(f'<text x="{sx(xv)}" y="{H - PAD + 15}" text-anchor="middle" font-size="10">{xv:.0f}</text>')
        yv = ymin + (ymax - ymin) * i / 5
        out.append(f'<text x="{x0 + PAD - 5}" y="{sy(yv) + 3}" text-anchor="end" font-size="10">{yv:.1f}</text>')
    out.append(f'<text x="{x0 + W / 2}" y="{H - 20}" text-anchor="middle" font-size="11">kbit/s (pose + texture + framing, 30 Hz)</text>')
    out.append(f'<text x="{x0 + 14}" y="{H / 2}" font-size="11" transform="rotate(-90 {x0 + 14} {H / 2})" text-anchor="middle">PSNR (dB)</text>')
    for i, ((run, codec), s) in enumerate(sorted(series.items())):
        c = COLOURS[i % len(COLOURS)]
        s = sorted(s, key=lambda r: float(r["total_kbps"]))
        line = " ".join(f"{sx(float(r['total_kbps'])):.1f},{sy(float(r[key])):.1f}" for r in s)
        out.append(f'<polyline points="{line}" fill="none" stroke="{c}" stroke-width="1.8"/>')
        for r in s:
            out.append(f'<circle cx="{sx(float(r["total_kbps"])):.1f}" cy="{sy(float(r[key])):.1f}" r="2.8" fill="{c}"/>')
        if sender_key:
            y = sy(float(s[0][sender_key]))
            out.append(f'<line x1="{x0 + PAD}" x2="{x0 + W - 15}" y1="{y:.1f}" y2="{y:.1f}" stroke="{c}" stroke-dasharray="4 3"/>')
        out.append(f'<rect x="{x0 + PAD + 8}" y="{32 + 14 * i}" width="10" height="3" fill="{c}"/>'
                   f'<text x="{x0 + PAD + 22}" y="{36 + 14 * i}" font-size="10">{run} ({codec})</text>')
    return out


body = panel(0, "psnr_vs_sender_db", "receiver vs sender's full-quality model")
body += panel(W, "receiver_psnr_db", "receiver vs ground truth (dashed: sender)", "sender_psnr_db")
svg = (f'<svg xmlns="http://www.w3.org/2000/svg" width="{2 * W}" height="{H}" '
       f'font-family="sans-serif"><rect width="100%" height="100%" fill="white"/>'
       + "".join(body) + "</svg>\n")
open(sys.argv[2], "w").write(svg)
