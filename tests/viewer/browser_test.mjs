// The web viewer in a real browser (issue 21): headless Chromium driven by puppeteer-core (pinned
// in viewer/package-lock.json), each page served by `btfc view` itself.
//   node browser_test.mjs VIEWER_DIR WORK CONFIG.json
// CONFIG: { btfc, chromium, query (the fixed camera / light, as URL parameters), cases: [{name,
// dir, reference (btfc render PNG of the same model, camera, light), min (dB, default 35), query
// (the viewer mode, default flat), mask ('disc': the sphere's pixels), wrong: {reference, what}}], broken:
// [{name, dir, expect (text the page must show)}], shots: [{name, dir, query}] }.
// Checks: every codec's flat-mode screenshot against `btfc render` (PSNR >= 35 dB on the
// material's pixels, sRGB 8-bit as both write them), and per case bounds (512 x 512 direction
// maps, the rsphere mode); renders of another scene must fail the bound (the comparison can
// fail); broken exports show their error on the page; two exports load side by side; shift-drag
// moves the light; shots draw the shape. Prints one line per check and "N passed, N failed".
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import { createRequire } from 'node:module';
import path from 'node:path';
import zlib from 'node:zlib';

const [viewerDir, work, configFile] = process.argv.slice(2);
const cfg = JSON.parse(fs.readFileSync(configFile, 'utf8'));
const puppeteer = createRequire(path.join(path.resolve(viewerDir), 'package.json'))('puppeteer-core');
const PSNR_MIN = 35;
let passed = 0, failed = 0;
const report = (ok, what) => { console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`); ok ? ++passed : ++failed; };

// 8-bit RGB / RGBA, non-interlaced PNG (what OpenImageIO and Chromium write) -> {w, h, ch, px}.
function readPng(file) {
  const b = fs.readFileSync(file);
  let off = 8, w = 0, h = 0, ch = 0;
  const idat = [];
  while (off < b.length) {
    const len = b.readUInt32BE(off), type = b.toString('latin1', off + 4, off + 8), d = b.subarray(off + 8, off + 8 + len);
    if (type === 'IHDR') {
      w = d.readUInt32BE(0), h = d.readUInt32BE(4);
      if (d[8] !== 8 || d[12] !== 0 || (d[9] !== 2 && d[9] !== 6)) throw new Error(`${file}: not an 8-bit RGB(A) non-interlaced PNG`);
      ch = d[9] === 6 ? 4 : 3;
    } else if (type === 'IDAT') idat.push(d);
    off += 12 + len;
  }
  const raw = zlib.inflateSync(Buffer.concat(idat)), stride = w * ch, px = Buffer.alloc(h * stride);
  for (let y = 0; y < h; ++y) {
    const f = raw[y * (stride + 1)], src = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; ++x) {
      const a = x >= ch ? px[y * stride + x - ch] : 0, up = y ? px[(y - 1) * stride + x] : 0;
      const c = x >= ch && y ? px[(y - 1) * stride + x - ch] : 0;
      const p = a + up - c, pa = Math.abs(p - a), pb = Math.abs(p - up), pc = Math.abs(p - c);
      const pred = [0, a, up, (a + up) >> 1, pa <= pb && pa <= pc ? a : pb <= pc ? up : c][f];
      px[y * stride + x] = (src[x] + pred) & 255;
    }
  }
  return { w, h, ch, px };
}

// PSNR (dB, peak 255) over the RGB of the material's pixels: in flat mode every pixel is a texel
// of the sample; pixels black in both images (unlit texels) are material too and count.
// mask 'disc': only the pixels btfc render's sphere covers (pixel centre inside the unit disc).
function psnr(a, b, mask) {
  if (a.w !== b.w || a.h !== b.h) throw new Error(`sizes differ: ${a.w}x${a.h} vs ${b.w}x${b.h}`);
  let se = 0, n = 0;
  for (let i = 0; i < a.w * a.h; ++i) {
    const x = ((i % a.w) + 0.5) / a.w * 2 - 1, y = 1 - (Math.floor(i / a.w) + 0.5) / a.h * 2;
    if (mask === 'disc' && x * x + y * y >= 1) continue;
    for (let c = 0; c < 3; ++c, ++n) se += (a.px[i * a.ch + c] - b.px[i * b.ch + c]) ** 2;
  }
  return se === 0 ? Infinity : 10 * Math.log10((255 * 255 * n) / se);
}

// `btfc view DIRS... --port 0`: resolves with {url, stop} once it printed its URL.
function serve(dirs) {
  return new Promise((resolve, reject) => {
    const p = spawn(cfg.btfc, ['view', ...dirs, '--port', '0', '--viewer', viewerDir], { stdio: ['ignore', 'pipe', 'pipe'] });
    let out = '', err = '';
    p.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/http:\/\/\S+/);
      if (m) resolve({ url: m[0], stop: () => p.kill('SIGTERM') });
    });
    p.stderr.on('data', (d) => { err += d; });
    p.on('exit', (code) => reject(new Error(`btfc view exited (${code}): ${err}`)));
  });
}

// One tab for every page (a new tab costs seconds on a loaded 2-core machine); each page gets its
// own `btfc view` server, stopped when the page is done.
let tab = null;
async function openPage(browser, dirs, query) {
  const srv = await serve(dirs);
  if (!tab) {
    tab = await browser.newPage();
    tab.on('pageerror', (e) => console.log(`  page error: ${e.message}`));
    await tab.setViewport({ width: 1400, height: 900, deviceScaleFactor: 1 });
  }
  const page = tab;
  await page.goto(`${srv.url}&${query}`);
  await page.waitForFunction(() => ['ready', 'error'].includes(document.body.dataset.state), { timeout: 60000 });
  return { page, srv };
}

// Screenshot of the first panel's canvas, exactly its pixels (zoom=1: one CSS pixel per texel).
async function shootCanvas(page, file) {
  const el = await page.$('#panel0 canvas');
  await el.screenshot({ path: file });
  return readPng(file);
}

const browser = await puppeteer.launch({
  executablePath: cfg.chromium, headless: true,
  // SwiftShader: Chromium's own software GL, the same on every machine without a GPU.
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'],
});
try {
  for (const c of cfg.cases) {
    const { page, srv } = await openPage(browser, [c.dir], `${cfg.query}&${c.query || 'mode=flat&zoom=1'}`);
    const state = await page.evaluate(() => document.body.dataset.state);
    if (state !== 'ready') {
      report(false, `${c.name}: the page did not load: ${await page.evaluate(() => window.btfcViewer.errors().join('; '))}`);
    } else {
      const shot = await shootCanvas(page, path.join(work, `${c.name.replace(/\W+/g, "_")}.viewer.png`));
      const ref = readPng(c.reference);
      const db = psnr(shot, ref, c.mask), min = c.min ?? PSNR_MIN;
      report(db >= min, `${c.name}: viewer vs btfc render PSNR ${db.toFixed(2)} dB (>= ${min}), ${shot.w}x${shot.h} pixels`);
      if (c.wrong) {  // the comparison must be able to fail: a render of another scene
        const wrong = psnr(shot, readPng(c.wrong.reference), c.mask);
        report(wrong < min, `${c.name}: against a render ${c.wrong.what} ${wrong.toFixed(2)} dB (< ${min}: the check can fail)`);
      }
    }
    srv.stop();
  }
  // Mip levels (issue 21, "the codec's level of detail"): every level of the export's mip chains
  // (fmf's eigen-textures) on the GPU, shown by the level-of-detail slider. Flat mode under a
  // directional light: every texel sees the same directions and fmf (color=rgb) is linear in its
  // eigen-textures, whose level k is the 2^k x 2^k box average of level 0, so level 1 must be the
  // 2 x 2 average of the level-0 picture (in linear light)
  // and the last level (1 x 1) the average of the whole sample; blocks with a pixel clipped at 0
  // or 255 are skipped.
  for (const l of cfg.lod || []) {
    const manifest = JSON.parse(fs.readFileSync(path.join(l.dir, 'manifest.json'), 'utf8'));
    const chains = manifest.textures.filter((t) => t.levels > 1);
    const { page, srv } = await openPage(browser, [l.dir], l.query);
    const lv = await page.evaluate(() => window.btfcViewer.levels()[0]);
    const want = Math.min(...chains.map((t) => t.levels));
    report(chains.length > 0 && chains.every((t) => lv.textures[t.name] === t.levels) && lv.mipLevels === want,
      `${l.name}: mip chains on the GPU ${JSON.stringify(lv.textures)}, ${lv.mipLevels} levels of detail (manifest: ` +
      `${chains.map((t) => `${t.name} ${t.levels}`).join(', ')})`);
    const shot = async (lod) => {
      await page.evaluate((x) => window.btfcViewer.set({ lod: x }), lod);
      return shootCanvas(page, path.join(work, `${l.name.replace(/\W+/g, '_')}.lod${lod}.png`));
    };
    const s0 = await shot(0), s1 = await shot(1), sl = await shot(want - 1);
    const lin = (c) => { c /= 255; return c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4; };
    const enc = (x) => 255 * (x <= 0.0031308 ? 12.92 * x : 1.055 * x ** (1 / 2.4) - 0.055);
    const px = (im, x, y, c) => im.px[(y * im.w + x) * im.ch + c];
    let se = 0, n = 0, blocky = true, changed = 0;
    for (let y = 0; y + 1 < s0.h; y += 2)
      for (let x = 0; x + 1 < s0.w; x += 2)
        for (let c = 0; c < 3; ++c) {
          const q = [[0, 0], [1, 0], [0, 1], [1, 1]];
          const v1 = q.map(([dx, dy]) => px(s1, x + dx, y + dy, c)), v0 = q.map(([dx, dy]) => px(s0, x + dx, y + dy, c));
          if (Math.max(...v1) - Math.min(...v1) > 1) blocky = false;
          changed += v0.some((v, i) => v !== v1[i]);
          // Clipped at either end (fmf's sum can dip below 0 at dark texels): the average of clipped
          // values is not the clipped average.
          if (Math.max(...v0, v1[0]) === 255 || Math.min(...v0, v1[0]) === 0) continue;
          se += (enc(v0.reduce((a, v) => a + lin(v), 0) / 4) - v1[0]) ** 2, ++n;
        }
    const db = 10 * Math.log10((255 * 255 * n) / Math.max(se, 1e-9));
    report(blocky && changed > 0 && db >= l.min,
      `${l.name}: level 1 is constant over 2 x 2 texels, differs from level 0 in ${changed} block channels, and equals ` +
      `the 2 x 2 average of level 0 at ${db.toFixed(2)} dB (>= ${l.min}; ${n} block channels unclipped)`);
    let mean = [0, 0, 0], spread = 0;
    for (let i = 0; i < s0.w * s0.h; ++i)
      for (let c = 0; c < 3; ++c) {
        mean[c] += lin(s0.px[i * s0.ch + c]) / (s0.w * s0.h);
        spread = Math.max(spread, Math.abs(sl.px[i * sl.ch + c] - sl.px[c]));
      }
    const top = [0, 1, 2].map((c) => sl.px[c]);
    const off = Math.max(...[0, 1, 2].map((c) => Math.abs(enc(mean[c]) - top[c])));
    report(spread === 0 && Math.max(...top) > 0 && off <= l.maxOff,
      `${l.name}: level ${want - 1} (1 x 1) is one colour ${top} over the sample, the level-0 average ${mean.map(enc).map((v) => v.toFixed(1))} ` +
      `(within ${l.maxOff}: ${off.toFixed(1)})`);
    srv.stop();
  }
  for (const b of cfg.broken) {
    const { page, srv } = await openPage(browser, [b.dir], cfg.query);
    const state = await page.evaluate(() => document.body.dataset.state);
    const shown = await page.evaluate(() => [...document.querySelectorAll('.error')].filter((e) => !e.hidden).map((e) => e.textContent).join(' | '));
    report(state === 'error' && shown.includes(b.expect), `${b.name}: page shows "${shown}" (expected to contain "${b.expect}")`);
    srv.stop();
  }
  if (cfg.side_by_side) {
    const { page, srv } = await openPage(browser, cfg.side_by_side, `${cfg.query}&mode=flat`);
    const info = await page.evaluate(() => [...document.querySelectorAll('.info')].map((t) => t.textContent));
    const ok = (await page.evaluate(() => document.body.dataset.state)) === 'ready' && info.length === 2 &&
      info.every((t) => /texture bytes\s*[\d.]+ KiB/.test(t) && /settings/.test(t));
    report(ok, `side by side: two panels with their bytes and settings`);
    // Shift-drag moves the light (theta, phi) instead of orbiting.
    const before = await page.evaluate(() => [...window.btfcViewer.settings.light]);
    const box = await (await page.$('#panel0 canvas')).boundingBox();
    const cx = box.x + box.width / 2, cy = box.y + box.height / 2;
    await page.keyboard.down('Shift');
    await page.mouse.move(cx, cy);
    await page.mouse.down();
    await page.mouse.move(cx + 60, cy + 30, { steps: 4 });
    await page.mouse.up();
    await page.keyboard.up('Shift');
    const after = await page.evaluate(() => [...window.btfcViewer.settings.light]);
    report(after[0] !== before[0] && after[1] !== before[1], `shift-drag moves the light: theta, phi ${before} -> ${after.map((x) => x.toFixed(0))}`);
    srv.stop();
  }
  for (const s of cfg.shots || []) {
    const { page, srv } = await openPage(browser, [s.dir], s.query);
    const img = await shootCanvas(page, path.join(work, `${s.name}.png`));
    // The shape must be on the canvas: pixels other than the clear colour (0x303034).
    let shape = 0;
    for (let i = 0; i < img.w * img.h; ++i)
      if (img.px[i * img.ch] !== 0x30 || img.px[i * img.ch + 1] !== 0x30 || img.px[i * img.ch + 2] !== 0x34) ++shape;
    report(shape > 0.1 * img.w * img.h, `${s.name}: ${(100 * shape / (img.w * img.h)).toFixed(0)} % of the canvas shows the material`);
    if (s.measure) {  // frame time (tests/viewer/shots.sh): seconds per frame on software GL
      const ms = await page.evaluate(() => window.btfcViewer.measure(3));
      console.log(`     ${s.name}: ${ms.toFixed(0)} ms / frame (${s.query})`);
    }
    srv.stop();
  }
} catch (e) {
  report(false, e.stack);
} finally {
  await browser.close();
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
