// `npm test`: node's test runner over the compiled tests (build-test/*.test.js; `npm run build`
// first). The live tests need QUADLOC_URL (and QUADLOC_KEYED_URL, ...): without them they are
// skipped, saying why. Node >= 18.
import { spawnSync } from "node:child_process";
import { readdirSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const dir = join(dirname(fileURLToPath(import.meta.url)), "..", "build-test");
const files = readdirSync(dir).filter((f) => f.endsWith(".test.js")).sort().map((f) => join(dir, f));
const r = spawnSync(process.execPath, ["--test", "--test-reporter=spec", ...files], { stdio: "inherit" });
process.exit(r.status ?? 1);
