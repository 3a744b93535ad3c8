// Regenerates src/generated/openapi.ts, the wire types, from the repository's OpenAPI document
// (docs/openapi.json, the one contract of the API) with openapi-typescript.
//
//   npm run generate           write src/generated/openapi.ts
//   npm run check:generated    exit 1 (naming the command to run) when the committed file is not
//                              what the generator makes from the current docs/openapi.json
//
// The header records the sha256 of the document it was made from; tests/sdk/test_sdk_contract.py
// compares it with docs/openapi.json without needing node.
import { createHash } from "node:crypto";
import { readFileSync, writeFileSync, mkdirSync } from "node:fs";
import { dirname, join, relative } from "node:path";
import { fileURLToPath } from "node:url";
import openapiTS, { astToString } from "openapi-typescript";

const here = dirname(fileURLToPath(import.meta.url));
const pkg = join(here, "..");
const spec = join(pkg, "..", "..", "docs", "openapi.json");
const out = join(pkg, "src", "generated", "openapi.ts");
const generatorVersion = JSON.parse(
  readFileSync(join(pkg, "node_modules", "openapi-typescript", "package.json"), "utf8"),
).version;

export async function generate() {
  const raw = readFileSync(spec);
  const sha256 = createHash("sha256").update(raw).digest("hex");
  const ast = await openapiTS(JSON.parse(raw.toString("utf8")), {
    // A field with a default is still optional in a request (the server fills it in).
    defaultNonNullable: false,
    // Free-form objects (map documents, build reports) are Record<string, unknown>.
    emptyObjectsUnknown: true,
    // Keep the document's order (it follows the API's sections).
    alphabetize: false,
  });
  const header =
    "// GENERATED FILE: do not edit. `npm run generate` (in sdk/typescript) rewrites it from\n" +
    `// docs/openapi.json with openapi-typescript ${generatorVersion}.\n` +
    `// openapi-sha256: ${sha256}\n\n`;
  return header + astToString(ast);
}

const text = await generate();
const rel = relative(process.cwd(), out) || out;
if (process.argv.includes("--check")) {
  let committed = "";
  try {
    committed = readFileSync(out, "utf8");
  } catch {
    committed = "";
  }
  if (committed !== text) {
    console.error(
      `${rel} is stale: docs/openapi.json changed (or the generator did). ` +
        "Run `npm run generate` in sdk/typescript, then rebuild and commit the file.",
    );
    process.exit(1);
  }
  console.log(`${rel} matches docs/openapi.json`);
} else {
  mkdirSync(dirname(out), { recursive: true });
  writeFileSync(out, text);
  console.log(`wrote ${rel}`);
}
