// Builds the browser client into a folder (default ../build/web): app.js bundled by esbuild from
// src/ (three.js, meshoptimizer's decoder, protobufjs, and proto/walkthrough.proto as text) and
// index.html. Run by the build (web/CMakeLists.txt) once ./vistream.sh has installed the npm
// packages (web/package-lock.json).
import { build } from 'esbuild';
import { copyFileSync, mkdirSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const out = resolve(process.argv[2] || join(here, '..', 'build', 'web'));
mkdirSync(out, { recursive: true });
await build({
  entryPoints: [join(here, 'src', 'main.js')],
  bundle: true,
  minify: true,
  sourcemap: true,
  format: 'iife',
  target: ['chrome110', 'firefox115', 'safari16'],
  loader: { '.proto': 'text' },
  outfile: join(out, 'app.js'),
  logLevel: 'warning',
});
copyFileSync(join(here, 'page', 'index.html'), join(out, 'index.html'));
console.log(`vistream web page built into ${out}`);
