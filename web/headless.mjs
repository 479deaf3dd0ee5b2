// Runs the browser client headless (Debian's chromium through puppeteer-core; WebGL 2 through
// SwiftShader) and prints its summary as JSON: the ctest suite's web tests and `vistream bench
// web` run it against a real server on loopback.
//
//   node web/headless.mjs --url URL [--seconds S] [--until-walk-done] [--size 1280x720]
//        [--screenshot FILE.png] [--id-passes N [--id-span S]] [--chromium PATH] [--insecure-tls]
//        [--until-sessions N [--min-walk S]]
//
// Prints one JSON object: the page's window.vistream.summary() at the end, the load timings
// (navigation to the first drawn frame), and, with --id-passes N, N id passes spread over the
// run (the objects each frame shows, with pixel counts). Exits 1 (message on stderr) when the
// page fails to load or reports an error state; the browser is always closed.
import puppeteer from 'puppeteer-core';
import { writeFileSync } from 'node:fs';

const args = process.argv.slice(2);
const opt = (name, fallback) => {
  const k = args.indexOf(`--${name}`);
  return k >= 0 ? args[k + 1] : fallback;
};
const flag = (name) => args.includes(`--${name}`);
const url = opt('url');
if (!url) {
  console.error('headless.mjs: --url is required');
  process.exit(2);
}
const seconds = Number(opt('seconds', '10'));
const [width, height] = opt('size', '1280x720').split('x').map(Number);
const screenshot = opt('screenshot', '');
const idPasses = Number(opt('id-passes', '0'));
// The id passes are spread over this many seconds of the walk, from when it starts (default: the
// whole run).
const idSpan = Number(opt('id-span', String(seconds)));
const chromium = opt('chromium', process.env.VISTREAM_CHROMIUM || '/usr/bin/chromium');
// Ends the run early once the page has opened this many sessions (a reconnect) and walked at
// least --min-walk seconds.
const untilSessions = Number(opt('until-sessions', '0'));
const minWalk = Number(opt('min-walk', '0'));

const browser = await puppeteer.launch({
  executablePath: chromium,
  headless: true,
  args: ['--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader', '--ignore-gpu-blocklist',
    `--window-size=${width},${height}`, '--disable-background-timer-throttling',
    '--disable-renderer-backgrounding', '--disable-backgrounding-occluded-windows',
    // Tests serve WSS with a certificate of their own CA, which chromium does not know.
    ...(flag('insecure-tls') ? ['--ignore-certificate-errors'] : [])],
  defaultViewport: { width, height },
  protocolTimeout: 600000,
});
let code = 0;
try {
  const page = await browser.newPage();
  const console_ = [];
  page.on('console', (m) => console_.push(m.text()));
  page.on('pageerror', (e) => console_.push(`page error: ${e.message}`));
  const started = Date.now();
  await page.goto(url, { waitUntil: 'load', timeout: 60000 });
  const passes = [];
  const until = started + seconds * 1000;
  const step = idPasses > 0 ? (idSpan * 1000) / (idPasses + 1) : 0;
  let nextPass = null;  // set once the walk has started
  for (;;) {
    const now = Date.now();
    const s = await page.evaluate(() => window.vistream ? window.vistream.summary() : null);
    if (s && (s.state === 'error')) break;
    if (flag('until-walk-done') && s && s.walk_done) break;
    if (untilSessions > 0 && s && s.sessions >= untilSessions && s.state === 'walking' && s.walk_s >= minWalk) break;
    if (now >= until) break;
    if (nextPass === null && s && s.walk_s > 0) nextPass = now + step;
    if (idPasses > 0 && nextPass !== null && passes.length < idPasses && now >= nextPass) {
      passes.push(await page.evaluate(() => window.vistream.idPass()));
      nextPass += step;
    }
    await new Promise((r) => setTimeout(r, 100));
  }
  const summary = await page.evaluate(() => window.vistream ? window.vistream.summary() : null);
  const timing = await page.evaluate(() => {
    const n = performance.getEntriesByType('navigation')[0];
    return n ? { response_end_ms: n.responseEnd, load_event_ms: n.loadEventEnd } : {};
  });
  if (screenshot) writeFileSync(screenshot, await page.screenshot({ type: 'png' }));
  const message = await page.evaluate(() => document.getElementById('message').textContent);
  const gl = await page.evaluate(() => {
    const c = document.createElement('canvas').getContext('webgl2');
    const d = c && c.getExtension('WEBGL_debug_renderer_info');
    return c ? (d ? c.getParameter(d.UNMASKED_RENDERER_WEBGL) : c.getParameter(c.RENDERER)) : 'no WebGL 2';
  });
  process.stdout.write(`${JSON.stringify({ url, size: [width, height], renderer: gl, timing, message, summary, id_passes: passes, console: console_.slice(-20) })}\n`);
  if (!summary || summary.state === 'error') {
    console.error(`headless.mjs: the page ${summary ? `says: ${summary.error}` : 'did not start'}`);
    code = 1;
  }
} catch (e) {
  console.error(`headless.mjs: ${e.message}`);
  code = 1;
} finally {
  await browser.close();
}
process.exit(code);
