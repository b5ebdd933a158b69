// Drives the viewer in Debian's headless chromium (puppeteer-core, software WebGL through
// SwiftShader) for scripts/viewer_test: one of
//   file  URL REFERENCE.png OUT.png     load the page at URL (a frame and viewpoint in its
//                                       query), screenshot the canvas into OUT.png, and print
//                                       the PSNR against REFERENCE.png (artex's own render)
//   bench URL N                         the page's frame rate over N back-to-back renders
//   live  URL SECONDS                   watch the live stream until it ends (or SECONDS) and
//                                       print the page's measurements (latency, frames shown)
//   play  URL                           play the file at its frame rate to the end and print the
//                                       page's measurements (frame rate, decode times)
//   shot  URL OUT.png                   a screenshot of the whole page (docs/images/)
// Prints one JSON line. Exit 77 when no browser can start (the caller skips), 1 on failure.
import fs from 'node:fs';
import puppeteer from 'puppeteer-core';

const [mode, url, a3, a4] = process.argv.slice(2);
const executablePath = process.env.ARTEX_CHROMIUM || '/usr/bin/chromium';
let browser;
try {
  browser = await puppeteer.launch({
    executablePath, headless: true,
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
      '--ignore-gpu-blocklist', '--window-size=1000,760'],
  });
} catch (e) {
  console.log(JSON.stringify({ skipped: `no browser could start (${executablePath}): ${e.message.split('\n')[0]}` }));
  process.exit(77);
}
const out = {};
try {
  const page = await browser.newPage();
  await page.setViewport({ width: 1000, height: 760, deviceScaleFactor: 1 });
  const logs = [];
  page.on('console', (m) => logs.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => logs.push(`pageerror: ${e.message}`));
  await page.goto(url, { waitUntil: 'load' });
  const waitReady = async (ms) => {
    await page.waitForFunction(() => window.artex && (window.artex.ready || window.artex.error), { timeout: ms });
    const error = await page.evaluate(() => window.artex.error);
    if (error) throw new Error(`page: ${error}`);
  };
  if (mode === 'file') {
    await waitReady(60000);
    await page.evaluate(() => window.artex.render());
    const reference = `data:image/png;base64,${fs.readFileSync(a3).toString('base64')}`;
    const r = await page.evaluate(async (refUrl) => {
      const canvas = document.getElementById('view');
      const img = new Image();
      img.src = refUrl;
      await img.decode();
      const W = canvas.width, H = canvas.height;
      if (img.width !== W || img.height !== H) return { error: `reference ${img.width}x${img.height}, canvas ${W}x${H}` };
      const c2 = new OffscreenCanvas(W, H).getContext('2d');
      c2.drawImage(img, 0, 0);
      const ref = c2.getImageData(0, 0, W, H).data;
      c2.clearRect(0, 0, W, H);
      c2.drawImage(canvas, 0, 0);
      const got = c2.getImageData(0, 0, W, H).data;
      let se = 0, seMasked = 0, n = 0, both = 0, onlyOne = 0;
      for (let i = 0; i < W * H * 4; i += 4) {
        let d2 = 0;
        for (let c = 0; c < 3; ++c) d2 += (ref[i + c] - got[i + c]) ** 2;
        se += d2;
        const a = ref[i] + ref[i + 1] + ref[i + 2] > 0, b = got[i] + got[i + 1] + got[i + 2] > 0;
        if (a || b) { seMasked += d2; ++n; }
        if (a && b) ++both; else if (a || b) ++onlyOne;
      }
      const psnr = (s, m) => 10 * Math.log10((255 * 255) / (s / (3 * m)));
      return {
        psnr_db: psnr(se, W * H), psnr_model_db: psnr(seMasked, n), model_pixels: n,
        silhouette_iou: both / Math.max(1, both + onlyOne), frame: window.artex.frame,
        codec: window.artex.codec, decode_ms_median: window.artex.summary().decode_ms_median,
      };
    }, reference);
    Object.assign(out, r);
    const canvas = await page.$('#view');
    await canvas.screenshot({ path: a4 });
  } else if (mode === 'bench') {
    await waitReady(60000);
    await page.evaluate(() => window.artex.bench(5));  // warm-up
    out.bench_fps = await page.evaluate((n) => window.artex.bench(n), +a3);
    out.frames = await page.evaluate(() => window.artex.frames);
  } else if (mode === 'live') {
    await page.waitForFunction(() => window.artex && (window.artex.liveDone || window.artex.error),
      { timeout: 1000 * +a3, polling: 200 }).catch(() => {});
    const error = await page.evaluate(() => window.artex.error);
    if (error) throw new Error(`page: ${error}`);
    Object.assign(out, await page.evaluate(() => window.artex.summary()));
    out.ended = await page.evaluate(() => window.artex.liveDone);
  } else if (mode === 'play') {
    await waitReady(60000);
    await page.waitForFunction(() => !window.artex.playing, { timeout: 120000, polling: 100 });
    Object.assign(out, await page.evaluate(() => window.artex.summary()));
  } else if (mode === 'shot') {
    await waitReady(60000);
    await page.evaluate(() => { window.artex.render(); });
    await new Promise((r) => setTimeout(r, 1200));  // one panel update
    await page.screenshot({ path: a3 });
  } else {
    throw new Error(`unknown mode ${mode}`);
  }
  out.console = logs.filter((l) => !l.startsWith('debug')).slice(0, 10);
  console.log(JSON.stringify(out));
  await browser.close();
} catch (e) {
  out.error = e.message;
  console.log(JSON.stringify(out));
  await browser.close();
  process.exit(1);
}
