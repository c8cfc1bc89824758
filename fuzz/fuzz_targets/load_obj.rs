//! OBJ loading from arbitrary bytes never panics; small meshes that load also bake.
#![no_main]

use libfuzzer_sys::fuzz_target;
use octrace_bake::{bake, BuildParams, Mesh, MeshFormat};

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = Mesh::from_bytes(data, MeshFormat::Obj, "fuzz.obj".as_ref(), None) {
        if mesh.triangles.len() <= 200 {
            let params = BuildParams { max_depth: Some(4), leaf_size: Some(2), ..BuildParams::auto() };
            if let Ok(scene) = bake(&mesh, &params) {
                scene.view().validate().expect("a bake is always valid");
            }
        }
    }
});
