// The parts of three.js the plan viewer (../static/viewer.js) draws with; bundled by
// esbuild into ../static/three.min.js as the global THREE (package.json: npm run build).
export {
  AmbientLight, ArrowHelper, AxesHelper, BoxGeometry, BufferAttribute, BufferGeometry,
  CanvasTexture, Color, ConeGeometry, CylinderGeometry, DirectionalLight, DoubleSide,
  Group, HemisphereLight, Line, LineBasicMaterial, LineSegments, Matrix4, Mesh,
  MeshBasicMaterial, MeshLambertMaterial, MeshPhongMaterial, MeshStandardMaterial,
  PerspectiveCamera, PlaneGeometry, Quaternion, RepeatWrapping, Scene, SphereGeometry,
  SRGBColorSpace, Vector3, WebGLRenderer, GridHelper, CapsuleGeometry, EdgesGeometry,
} from "three";
export { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
