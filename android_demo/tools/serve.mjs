#!/usr/bin/env node
// A small static file server for the phone app (no dependencies).
//
//   node tools/serve.mjs [--port 8080] [--host 127.0.0.1] [--root www]
//
// Prints "serving http://HOST:PORT/" once listening (--port 0 picks a free port). Binds to
// 127.0.0.1 by default: a phone reaches it through `adb reverse tcp:8080 tcp:8080` (then
// http://localhost:8080 on the phone is a secure context, which the camera needs).
// Serves .mjs/.js as JavaScript and .wasm as application/wasm (needed for streaming compile),
// and never lets a path leave the root folder.

import { createReadStream, statSync } from 'node:fs';
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

function parseArgs(argv) {
  const args = { port: 8080, host: '127.0.0.1', root: join(HERE, 'www') };
  for (let i = 0; i < argv.length; i += 2) {
    const [key, value] = [argv[i], argv[i + 1]];
    if (value === undefined || !['--port', '--host', '--root'].includes(key)) {
      throw new Error(`unknown argument ${JSON.stringify(key)}; usage: node tools/serve.mjs [--port N] [--host ADDR] [--root DIR]`);
    }
    args[key.slice(2)] = key === '--port' ? Number(value) : value;
  }
  if (!Number.isInteger(args.port) || args.port < 0 || args.port > 65535) throw new Error(`invalid --port ${args.port}; valid: 0..65535`);
  args.root = resolve(args.root);
  return args;
}

/** Create (not start) the server for a root folder. */
export function createStaticServer(root) {
  return createServer((req, res) => {
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
    res.writeHead(200, {
      'Content-Type': TYPES[extname(file)] || 'application/octet-stream',
      'Content-Length': stat.size,
      'Cache-Control': 'no-cache',
    });
    if (req.method === 'HEAD') res.end();
    else createReadStream(file).pipe(res);
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
  const server = createStaticServer(args.root);
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
