// The meshes the material is shown on: a plane, a sphere and a draped cloth, each a parametric
// surface P(u, v). The BTF needs a continuous tangent frame, not only normals: its directions are
// given in the sample's frame (x = texture u, y = up in the texture image, z = normal), so every
// vertex carries t = dP/du and the BTF texture coordinate (u, v with v = image row, downwards),
// and the shader completes the frame with b = n x t.
import * as THREE from 'three';

// uvScale: texture repeats along u and v. Derivatives are taken numerically so a new shape is
// only its P(u, v).
function parametric(P, nu, nv, uvScale, v0 = 0, v1 = 1) {
  const pos = [], nor = [], tan = [], uv = [], idx = [];
  const h = 1e-4;
  for (let j = 0; j <= nv; ++j) {
    const v = v0 + (v1 - v0) * (j / nv);
    for (let i = 0; i <= nu; ++i) {
      const u = i / nu;
      const p = P(u, v);
      const pu = P(u + h, v).sub(P(u - h, v));
      const pv = P(u, v - h).sub(P(u, v + h));  // -dP/dv: "up" in the texture image
      const n = new THREE.Vector3().crossVectors(pu, pv).normalize();
      pos.push(p.x, p.y, p.z);
      nor.push(n.x, n.y, n.z);
      tan.push(...pu.normalize().toArray());
      uv.push(u * uvScale[0], v * uvScale[1]);
    }
  }
  for (let j = 0; j < nv; ++j)
    for (let i = 0; i < nu; ++i) {
      const a = j * (nu + 1) + i, b = a + 1, c = a + nu + 1, d = c + 1;
      idx.push(a, c, b, b, c, d);
    }
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
  g.setAttribute('normal', new THREE.Float32BufferAttribute(nor, 3));
  g.setAttribute('tangent3', new THREE.Float32BufferAttribute(tan, 3));
  g.setAttribute('btfuv', new THREE.Float32BufferAttribute(uv, 2));
  g.setIndex(idx);
  return g;
}

const V = (x, y, z) => new THREE.Vector3(x, y, z);

// World: z is up; the plane is the flat sample of `btfc render` (normal +z, texture row 0 at +y).
export function makeShape(name, repeat = 1) {
  switch (name) {
    case 'plane':
      return parametric((u, v) => V((u - 0.5) * 2, (0.5 - v) * 2, 0), 1, 1, [repeat, repeat]);
    case 'sphere':
      // As `btfc render --shape sphere`: the texture wraps twice around the z axis (phi from +x
      // towards +y) and once from pole to pole; the poles are left open (t is undefined there).
      return parametric((u, v) => {
        const ph = 2 * Math.PI * u, th = Math.PI * v;
        return V(Math.sin(th) * Math.cos(ph), Math.sin(th) * Math.sin(ph), Math.cos(th));
      }, 128, 64, [2 * repeat, repeat], 0.005, 0.995);
    case 'cloth':
      // A cloth hanging over a bar: folds along u that deepen towards the hem, so the light
      // meets the weave at grazing and backlit angles.
      return parametric((u, v) => {
        const fold = 0.16 * Math.sin(2 * Math.PI * 2.5 * u + 0.6) * (0.25 + 0.75 * v);
        return V((u - 0.5) * 2.2, -0.9 * Math.sin(1.2 * v) + fold * 0.3, 0.9 - 1.9 * v * v + fold);
      }, 160, 96, [2 * repeat, 2 * repeat]);
    default:
      throw new Error(`unknown shape ${name}`);
  }
}
