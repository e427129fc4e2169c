#!/usr/bin/env node
// Decodes frames with npm's candied (an independent DBC decoder) for pumptherm's cross-check test
// (tests/protocol/codec_candied_test.cpp).
//
//   node decode.js FILE.dbc FRAMES.txt
//
// FRAMES.txt: one frame per line, "<message name> <payload hex>". Output, one line per signal:
//   sig <frame index> <signal name> <raw> <value>
// and first, one line per signal definition as candied parsed it:
//   def <message name> <signal name> <start bit> <length> <Intel|Motorola> <signed 0|1> <factor> <offset>
// Numbers are printed with JavaScript's shortest round-trip form.
'use strict';
const fs = require('fs');
const { Dbc, Can } = require('candied');

/// The Motorola raw value from candied's bit string, sliced from the MSB (sawtooth position
/// 8 * floor(start / 8) + 7 - start % 8 in the MSB-first string) for `length` bits.
function motorolaRaw(can, payload, sig) {
  if (sig.endian !== 'Motorola') return '-';
  const bits = can.payload2Binary(payload, 'Motorola');
  const msb = 8 * Math.floor(sig.startBit / 8) + (7 - (sig.startBit % 8));
  const field = bits.slice(msb, msb + sig.length).join('');
  if (field.length !== sig.length) return 'NaN';
  return String(sig.signed ? can.bin2decSigned(field) : can.bin2dec(field));
}

function main() {
  const [dbcPath, framesPath] = process.argv.slice(2);
  if (!dbcPath || !framesPath) {
    process.stderr.write('usage: node decode.js FILE.dbc FRAMES.txt\n');
    process.exit(2);
  }
  const dbc = new Dbc();
  const data = dbc.load(fs.readFileSync(dbcPath, 'utf8'));
  const can = new Can();
  can.database = data;
  const out = [];
  for (const [msgName, msg] of data.messages) {
    for (const [sigName, sig] of msg.signals) {
      out.push(`def ${msgName} ${sigName} ${sig.startBit} ${sig.length} ${sig.endian} ${sig.signed ? 1 : 0} ${sig.factor} ${sig.offset} ${sig.multiplex || '-'}`);
    }
  }
  const lines = fs.readFileSync(framesPath, 'utf8').split('\n');
  lines.forEach((line, index) => {
    if (line.trim() === '') return;
    const [msgName, hex] = line.trim().split(/\s+/);
    const msg = data.messages.get(msgName);
    if (!msg) {
      out.push(`nomsg ${index} ${msgName}`);
      return;
    }
    const payload = [];
    for (let i = 0; i + 1 < (hex || '').length; i += 2) payload.push(parseInt(hex.substr(i, 2), 16));
    for (const [sigName, sig] of msg.signals) {
      const bound = can.decodeSignal(payload, sig);
      out.push(`sig ${index} ${sigName} ${bound.rawValue} ${bound.value} ${motorolaRaw(can, payload, sig)}`);
    }
  });
  process.stdout.write(out.join('\n') + '\n');
}

main();
