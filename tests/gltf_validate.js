// Runs the Khronos glTF validator (npm gltf-validator, a library) on one .glb or .gltf and
// prints its report as JSON on stdout. Used by tests/gltf_validator_test.cpp.
//   node tests/gltf_validate.js PATH/TO/node_modules/gltf-validator FILE
'use strict';
const fs = require('fs');
const path = require('path');

const [validatorDir, file] = process.argv.slice(2);
if (!validatorDir || !file) {
  console.error('usage: node gltf_validate.js VALIDATOR_DIR FILE');
  process.exit(2);
}
const validator = require(path.resolve(validatorDir));
const bytes = new Uint8Array(fs.readFileSync(file));
validator
  .validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,  // no limit
    // A .gltf's .bin lies beside it.
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  })
  .then((report) => console.log(JSON.stringify(report)))
  .catch((error) => {
    console.error(`gltf-validator failed: ${error}`);
    process.exit(1);
  });
