// Builds the front end into ../src/trustseek/static/app/ (served by `trustseek serve`).
import { build } from "esbuild";
import { cpSync, mkdirSync, readdirSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const out = join(here, "..", "src", "trustseek", "static", "app");
mkdirSync(out, { recursive: true });

await build({
  entryPoints: { participant: join(here, "src", "participant.ts"), dashboard: join(here, "src", "dashboard.ts") },
  outdir: out,
  bundle: true,
  minify: true,
  sourcemap: true,
  format: "esm",
  target: ["es2020"],
  logLevel: "warning",
});
for (const f of readdirSync(join(here, "public"))) cpSync(join(here, "public", f), join(out, f));
console.log(`front end built into ${out}`);
