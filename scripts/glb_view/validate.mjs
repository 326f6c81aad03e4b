// Dev-only: the Khronos glTF validator on GLB files; prints its counts per file.
//   node scripts/glb_view/validate.mjs a.glb b.glb ...   (NODE_PATH=/tmp/glbview/node_modules)
import { createRequire } from 'module';
import { readFileSync } from 'fs';
const require = createRequire(process.env.NODE_PATH ? process.env.NODE_PATH + '/' : import.meta.url);
const validator = require('gltf-validator');
for (const path of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(path)), { maxIssues: 50 });
  const i = report.issues;
  console.log(`${path}: errors ${i.numErrors}, warnings ${i.numWarnings}, infos ${i.numInfos}, hints ${i.numHints}`);
  for (const m of i.messages) console.log(`  [${m.severity}] ${m.code} ${m.pointer ?? ''}: ${m.message}`);
}
