// Service worker: makes the app work offline after its first load.
//
// install:  fetch precache.json (written by tools/build.mjs: every app file, the three
//           onnxruntime-web files and the bundle, each with its SHA-256) and cache all of it in
//           a cache named after its version. Install fails (and the old version stays) when
//           any file cannot be fetched, so a phone never ends up with half an app.
// activate: delete the caches of older versions.
// fetch:    precache.json goes network-first (so an online visit sees a new version);
//           everything else cache-first, falling back to the network.
//
// The page registers `sw.js?v=<version>`; a new version therefore installs a new worker.

const PREFIX = 'crossing-assist-';
const VERSION = new URL(self.location.href).searchParams.get('v') || 'dev';
const CACHE = PREFIX + VERSION;

self.addEventListener('install', (event) => {
  event.waitUntil((async () => {
    const resp = await fetch('precache.json', { cache: 'no-store' });
    if (!resp.ok) throw new Error(`precache.json: HTTP ${resp.status}`);
    const list = await resp.json();
    const cache = await caches.open(CACHE);
    const urls = ['./', 'precache.json', ...list.files.map((f) => f.url)];
    await cache.addAll(urls.map((u) => new Request(u, { cache: 'no-store' })));
    await self.skipWaiting();
  })());
});

self.addEventListener('activate', (event) => {
  event.waitUntil((async () => {
    for (const name of await caches.keys()) {
      if (name.startsWith(PREFIX) && name !== CACHE) await caches.delete(name);
    }
    await self.clients.claim();
  })());
});

self.addEventListener('fetch', (event) => {
  const req = event.request;
  if (req.method !== 'GET' || new URL(req.url).origin !== self.location.origin) return;
  const path = new URL(req.url).pathname;
  if (path.endsWith('/precache.json')) {
    // A slow network must not stall the app: after 3 s the cached copy answers.
    const ctl = new AbortController();
    const timer = setTimeout(() => ctl.abort(), 3000);
    event.respondWith(fetch(req, { cache: 'no-store', signal: ctl.signal })
      .then((r) => (r.ok ? r : Promise.reject(new Error(`HTTP ${r.status}`))))
      .catch(() => caches.match(req, { ignoreSearch: true }))
      .finally(() => clearTimeout(timer)));
    return;
  }
  event.respondWith((async () => {
    const cache = await caches.open(CACHE);
    const hit = await cache.match(req, { ignoreSearch: true });
    if (hit) return hit;
    if (req.mode === 'navigate') {
      const shell = await cache.match('./');
      try {
        return await fetch(req);
      } catch (err) {
        if (shell) return shell;
        throw err;
      }
    }
    return fetch(req);
  })());
});
