// SPDX-License-Identifier: MIT
// Built into fixed file names (index.html, assets/app.js, assets/app.css) that the server
// embeds; no external resources: the dashboard works on an isolated incident network.
import { defineConfig } from 'vite';

export default defineConfig({
  base: '/',
  build: {
    target: 'es2020',
    emptyOutDir: true,
    modulePreload: { polyfill: false },
    rollupOptions: {
      output: {
        entryFileNames: 'assets/app.js',
        chunkFileNames: 'assets/[name].js',
        assetFileNames: 'assets/[name][extname]',
      },
    },
  },
});
