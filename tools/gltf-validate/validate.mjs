// Validate glTF files with the Khronos glTF Validator; prints one JSON summary per file
// ({file, errors, warnings, messages: first 20}) and exits 1 when any file has errors or warnings.
import { readFile } from 'node:fs/promises';
import validator from 'gltf-validator';

let bad = false;
for (const file of process.argv.slice(2)) {
  const bytes = new Uint8Array(await readFile(file));
  const report = await validator.validateBytes(bytes, { maxIssues: 1000 });
  const i = report.issues;
  console.log(JSON.stringify({
    file,
    errors: i.numErrors,
    warnings: i.numWarnings,
    messages: i.messages.slice(0, 20).map((m) => `${m.code} ${m.pointer ?? ''}: ${m.message}`),
  }));
  if (i.numErrors > 0 || i.numWarnings > 0) bad = true;
}
process.exit(bad ? 1 : 0);
