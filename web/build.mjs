// Copy the web view's JavaScript dependencies from node_modules into the Python package.
//
// Run `npm ci && npm run build` in web/ after changing the pinned three.js version in package.json
// (and package-lock.json). The copies are committed under unetyemu_ecs/view/static/vendor/, so
// `pip install` needs no npm and the page loads nothing from the internet; a test checks that they
// are byte-identical to what the pinned npm package contains. No bundler: the files stay the ES
// modules three.js publishes, resolved in the page by an import map (index.html).
import { copyFileSync, mkdirSync, readFileSync, rmSync, writeFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const vendor = join(here, "..", "unetyemu_ecs", "view", "static", "vendor");
const three = join(here, "node_modules", "three");

// vendor path -> path inside the npm package "three"
export const FILES = {
  "three.module.min.js": "build/three.module.min.js",
  "three.core.min.js": "build/three.core.min.js",
  "addons/controls/OrbitControls.js": "examples/jsm/controls/OrbitControls.js",
  "addons/renderers/CSS2DRenderer.js": "examples/jsm/renderers/CSS2DRenderer.js",
  "LICENSE": "LICENSE",
};

const version = JSON.parse(readFileSync(join(three, "package.json"), "utf8")).version;
rmSync(vendor, { recursive: true, force: true });
for (const [dest, src] of Object.entries(FILES)) {
  mkdirSync(dirname(join(vendor, dest)), { recursive: true });
  copyFileSync(join(three, src), join(vendor, dest));
}
writeFileSync(join(vendor, "VERSION.json"),
  JSON.stringify({ package: "three", version, files: FILES }, null, 2) + "\n");
console.log(`three ${version}: ${Object.keys(FILES).length} files -> ${vendor}`);
