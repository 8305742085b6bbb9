#!/usr/bin/env node
// A small static file server for the phone app (no dependencies).
//
//   node tools/serve.mjs [--port 8080] [--host 127.0.0.1] [--root www]
//
// Prints "serving http://HOST:PORT/" once listening (--port 0 picks a free port). Binds to
// 127.0.0.1 by default: a phone reaches it through `adb reverse tcp:8080 tcp:8080` (then
// http://localhost:8080 on the phone is a secure context, which the camera needs).
// Serves .mjs/.js as JavaScript and .wasm as application/wasm (needed for streaming compile),
// and never lets a path leave the root folder. Every response carries the cross-origin
// isolation headers (COOP same-origin + COEP require-corp), which onnxruntime-web needs for
// its multi-threaded WASM (SharedArrayBuffer); a host serving the built www/ must send them
// too, or the app runs on one thread. Where the build wrote a gzip twin (FILE.gz) and the
// client accepts gzip, the twin is sent with Content-Encoding: gzip.
// --log prints one line per request to stdout: "request GET /path 200 BYTES_SENT".

import { createReadStream, existsSync, statSync } from 'node:fs';
import { createServer } from 'node:http';
import { dirname, extname, join, normalize, resolve, sep } from 'node:path';
import { fileURLToPath } from 'node:url';

const HERE = dirname(dirname(fileURLToPath(import.meta.url)));
const TYPES = {
  '.html': 'text/html; charset=utf-8',
  '.js': 'text/javascript; charset=utf-8',
  '.mjs': 'text/javascript; charset=utf-8',
  '.css': 'text/css; charset=utf-8',
  '.json': 'application/json; charset=utf-8',
  '.webmanifest': 'application/manifest+json; charset=utf-8',
  '.wasm': 'application/wasm',
  '.onnx': 'application/octet-stream',
  '.svg': 'image/svg+xml',
  '.png': 'image/png',
};

/** Headers every response carries: cross-origin isolation (threads in onnxruntime-web). */
export const ISOLATION_HEADERS = {
  'Cross-Origin-Opener-Policy': 'same-origin',
  'Cross-Origin-Embedder-Policy': 'require-corp',
  'Cross-Origin-Resource-Policy': 'same-origin',
};

function parseArgs(argv) {
  const args = { port: 8080, host: '127.0.0.1', root: join(HERE, 'www'), log: false };
  for (let i = 0; i < argv.length; i += 2) {
    if (argv[i] === '--log') {
      args.log = true;
      i -= 1;
      continue;
    }
    const [key, value] = [argv[i], argv[i + 1]];
    if (value === undefined || !['--port', '--host', '--root'].includes(key)) {
      throw new Error(`unknown argument ${JSON.stringify(key)}; usage: node tools/serve.mjs [--port N] [--host ADDR] [--root DIR] [--log]`);
    }
    args[key.slice(2)] = key === '--port' ? Number(value) : value;
  }
  if (!Number.isInteger(args.port) || args.port < 0 || args.port > 65535) throw new Error(`invalid --port ${args.port}; valid: 0..65535`);
  args.root = resolve(args.root);
  return args;
}

/** Create (not start) the server for a root folder. */
export function createStaticServer(root, { log = false } = {}) {
  return createServer((req, res) => {
    let sent = 0;
    if (log) {
      res.on('finish', () => console.log(`request ${req.method} ${req.url} ${res.statusCode} ${req.method === 'HEAD' ? 0 : sent}`));
    }
    let path;
    try {
      path = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    } catch {
      res.writeHead(400).end('bad request');
      return;
    }
    if (path.endsWith('/')) path += 'index.html';
    const file = normalize(join(root, path));
    if (file !== root && !file.startsWith(root + sep)) {
      res.writeHead(403).end('forbidden');
      return;
    }
    let stat;
    try {
      stat = statSync(file);
    } catch {
      stat = null;
    }
    if (!stat || !stat.isFile()) {
      res.writeHead(404, { 'Content-Type': 'text/plain' }).end('not found');
      return;
    }
    const gz = `${file}.gz`;
    const useGz = /\bgzip\b/.test(req.headers['accept-encoding'] || '') && existsSync(gz);
    sent = useGz ? statSync(gz).size : stat.size;
    res.writeHead(200, {
      'Content-Type': TYPES[extname(file)] || 'application/octet-stream',
      'Content-Length': sent,
      'Cache-Control': 'no-cache',
      Vary: 'Accept-Encoding',
      ...(useGz ? { 'Content-Encoding': 'gzip' } : {}),
      ...ISOLATION_HEADERS,
    });
    if (req.method === 'HEAD') res.end();
    else createReadStream(useGz ? gz : file).pipe(res);
  });
}

function main() {
  let args;
  try {
    args = parseArgs(process.argv.slice(2));
  } catch (err) {
    console.error(`error: ${err.message}`);
    process.exit(2);
  }
  const server = createStaticServer(args.root, { log: args.log });
  server.on('error', (err) => {
    console.error(`error: cannot serve on ${args.host}:${args.port}: ${err.message}`);
    process.exit(2);
  });
  server.listen(args.port, args.host, () => {
    const { address, port } = server.address();
    console.log(`serving http://${address}:${port}/ from ${args.root}`);
  });
  const stop = () => {
    server.close(() => process.exit(0));
    server.closeAllConnections();
  };
  process.on('SIGTERM', stop);
  process.on('SIGINT', stop);
}

if (process.argv[1] && resolve(process.argv[1]) === fileURLToPath(import.meta.url)) main();
