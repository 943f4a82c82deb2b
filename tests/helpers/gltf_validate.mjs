// Runs the Khronos glTF-Validator (npm gltf-validator) on each file named on the command line and prints one
// JSON line per file: {file, numErrors, numWarnings, messages: [{code, severity, pointer, message}]}.
// Severity: 0 error, 1 warning, 2 info, 3 hint (the validator's own numbering).
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";

const require = createRequire(path.join(process.cwd(), "package.json"));
const validator = require("gltf-validator");

for (const file of process.argv.slice(2)) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,  // all of them
    externalResourceFunction: (uri) => new Promise((resolve, reject) => {
      const full = path.resolve(path.dirname(file), decodeURIComponent(uri));
      if (path.dirname(full) !== path.resolve(path.dirname(file))) { reject(new Error("outside the folder")); return; }
      fs.readFile(full, (err, data) => (err ? reject(err) : resolve(new Uint8Array(data))));
    }),
  });
  const messages = report.issues.messages.map((m) => ({ code: m.code, severity: m.severity, pointer: m.pointer ?? "",
                                                         message: m.message }));
  console.log(JSON.stringify({ file, numErrors: report.issues.numErrors, numWarnings: report.issues.numWarnings,
                               messages }));
}
