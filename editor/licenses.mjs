// Writes the licences of every npm package that esbuild put into the bundle next to it
// (vendor/LICENSES.txt), from the metafile esbuild wrote (meta.json).
import { readFileSync, writeFileSync, readdirSync, unlinkSync } from "node:fs";
import { join } from "node:path";

const meta = JSON.parse(readFileSync("meta.json", "utf8"));
const packages = new Set();
for (const input of Object.keys(meta.inputs)) {
  const m = input.match(/node_modules\/((?:@[^/]+\/)?[^/]+)\//);
  if (m) packages.add(m[1]);
}
let out = "Third-party code in codemirror.min.js (bundled by esbuild from the npm registry)\n";
for (const name of [...packages].sort()) {
  const dir = join("node_modules", name);
  const pkg = JSON.parse(readFileSync(join(dir, "package.json"), "utf8"));
  const file = readdirSync(dir).find((f) => /^licen[cs]e/i.test(f));
  out += `\n${"=".repeat(78)}\n${name} ${pkg.version} (${pkg.license})\n${"=".repeat(78)}\n`;
  out += file ? readFileSync(join(dir, file), "utf8") : `license: ${pkg.license}\n`;
}
writeFileSync("../src/csdf/editor/static/vendor/LICENSES.txt", out);
unlinkSync("meta.json");
console.log(`licences of ${packages.size} packages written`);
