//! Tests of the mesh file loaders and of path resolution.

use super::super::ShapeDesc;
use super::*;

/// A fresh scratch directory under the system temp dir.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("modesuite-shapes-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A unit cube as quads, the faces written with negative (relative) indices and `v/vt/vn` forms.
const CUBE_OBJ: &str = "# unit cube\no cube\n\
    v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
    vt 0 0\nvn 0 0 1\n\
    f -8/1/1 -5/1/1 -6/1/1 -7/1/1\n\
    f 5//1 6//1 7//1 8//1\n\
    f 1 2 6 5\n\
    f 2/1 3/1 7/1 6/1\n\
    f 3 4 8 7\n\
    f 4 1 5 8\n";

#[test]
fn obj_quads_and_negative_indices() {
    let dir = temp_dir("obj");
    std::fs::write(dir.join("cube.obj"), CUBE_OBJ).unwrap();
    let ctx = ShapeContext::new(&dir);
    let s = ShapeDesc::mesh_file("cube.obj").surface(&ctx).unwrap();
    assert_eq!((s.positions.len(), s.triangles.len()), (8, 12));
    assert!(s.is_closed());
    println!(
        "OBJ cube: enclosed volume {} (expected 1, tol 1e-12)",
        s.enclosed_volume()
    );
    assert!((s.enclosed_volume() - 1.0).abs() < 1e-12);
    let err = ShapeDesc::mesh_file("cube.obj")
        .volume(&ctx)
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(err.contains("not implemented"), "{err}");

    std::fs::write(dir.join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n").unwrap();
    let err = load_surface_file(&dir.join("bad.obj"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(err.contains("bad.obj:4:"), "{err}");
    std::fs::write(
        dir.join("range.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 9\n",
    )
    .unwrap();
    let err = load_surface_file(&dir.join("range.obj"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(
        err.contains("range.obj:5:") && err.contains("vertex 9"),
        "{err}"
    );
    std::fs::write(dir.join("nan.obj"), "v 0 nan 0\n").unwrap();
    assert!(load_surface_file(&dir.join("nan.obj"))
        .unwrap_err()
        .to_string()
        .contains("nan.obj:1:"));
    let _ = std::fs::remove_dir_all(&dir);
}

fn tet_corners() -> [[f32; 3]; 4] {
    [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ]
}
/// Outward faces of the corner tetrahedron.
const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

#[test]
fn stl_binary_and_ascii_weld_vertices() {
    let dir = temp_dir("stl");
    let p = tet_corners();
    let mut bin = vec![0u8; 80];
    bin.extend_from_slice(&(FACES.len() as u32).to_le_bytes());
    for f in FACES {
        bin.extend_from_slice(&[0u8; 12]);
        for &v in &f {
            for x in p[v] {
                bin.extend_from_slice(&x.to_le_bytes());
            }
        }
        bin.extend_from_slice(&[0u8; 2]);
    }
    // A binary file whose header starts with "solid" must still be read as binary.
    bin[..5].copy_from_slice(b"solid");
    std::fs::write(dir.join("tet.stl"), &bin).unwrap();
    let mut ascii = String::from("solid tet\n");
    for f in FACES {
        ascii.push_str("  facet normal 0 0 0\n    outer loop\n");
        for &v in &f {
            ascii.push_str(&format!(
                "      vertex {} {} {}\n",
                p[v][0], p[v][1], p[v][2]
            ));
        }
        ascii.push_str("    endloop\n  endfacet\n");
    }
    ascii.push_str("endsolid tet\n");
    std::fs::write(dir.join("tet_ascii.STL"), &ascii).unwrap();
    for file in ["tet.stl", "tet_ascii.STL"] {
        let s = load_surface_file(&dir.join(file)).unwrap();
        assert_eq!(
            (s.positions.len(), s.triangles.len()),
            (4, 4),
            "{file}: welded"
        );
        assert!(s.is_closed());
        assert!((s.enclosed_volume() - 1.0 / 6.0).abs() < 1e-12);
    }
    std::fs::write(
        dir.join("broken.stl"),
        "solid x\n facet normal 0 0 1\n outer loop\n vertex 0 0\n",
    )
    .unwrap();
    let err = load_surface_file(&dir.join("broken.stl"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(err.contains("broken.stl:4:"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two tetrahedra sharing a face (the second stored inverted), a boundary triangle element and an
/// unused node.
const MSH: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n\
    $PhysicalNames\n1\n3 1 \"body\"\n$EndPhysicalNames\n\
    $Nodes\n2 6 1 6\n\
    0 1 0 1\n6\n0 0 0\n\
    3 1 0 5\n1\n2\n3\n4\n5\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n0 0 0\n\
    $EndNodes\n\
    $Elements\n2 3 1 3\n\
    2 1 2 1\n1 1 2 3\n\
    3 1 4 2\n2 5 1 2 3\n3 4 1 2 3\n\
    $EndElements\n";

#[test]
fn gmsh_msh41_tets_and_reorientation() {
    let dir = temp_dir("msh");
    std::fs::write(dir.join("two.msh"), MSH).unwrap();
    let loaded = load_volume_file(&dir.join("two.msh")).unwrap();
    println!(
        "msh: {} tets, {} nodes, reoriented {}, dropped {}",
        loaded.mesh.tets.len(),
        loaded.mesh.nodes.len(),
        loaded.reoriented,
        loaded.dropped_nodes
    );
    assert_eq!(loaded.mesh.tets.len(), 2);
    assert_eq!(loaded.mesh.nodes.len(), 5);
    assert_eq!((loaded.reoriented, loaded.dropped_nodes), (1, 1));
    assert!(!loaded.quadratic_reduced);
    assert_eq!(loaded.mesh.quality().inverted, 0);
    let s = ShapeDesc::mesh_file("two.msh")
        .surface(&ShapeContext::new(&dir))
        .unwrap();
    assert!(s.is_closed());
    assert_eq!(s.triangles.len(), 6);
    assert!((s.enclosed_volume() - loaded.mesh.volume()).abs() < 1e-12);

    // 10-node tetrahedra keep their corners.
    let tet10 = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 10 1 10\n3 1 0 10\n\
        1\n2\n3\n4\n5\n6\n7\n8\n9\n10\n\
        0 0 0\n1 0 0\n0 1 0\n0 0 1\n0.5 0 0\n0.5 0.5 0\n0 0.5 0\n0 0 0.5\n0 0.5 0.5\n0.5 0 0.5\n\
        $EndNodes\n$Elements\n1 1 1 1\n3 1 11 1\n1 1 2 3 4 5 6 7 8 10 9\n$EndElements\n";
    std::fs::write(dir.join("quad.msh"), tet10).unwrap();
    let loaded = load_volume_file(&dir.join("quad.msh")).unwrap();
    assert!(loaded.quadratic_reduced);
    assert_eq!(
        (
            loaded.mesh.nodes.len(),
            loaded.mesh.tets.len(),
            loaded.dropped_nodes
        ),
        (4, 1, 6)
    );

    std::fs::write(
        dir.join("old.msh"),
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n",
    )
    .unwrap();
    let err = load_volume_file(&dir.join("old.msh"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(err.contains("2.2") && err.contains("4.1"), "{err}");
    let bad = MSH.replace("2 5 1 2 3", "2 5 1 2 77");
    std::fs::write(dir.join("bad.msh"), bad).unwrap();
    let err = load_volume_file(&dir.join("bad.msh"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(err.contains("bad.msh:30:") && err.contains("77"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn medit_vertices_and_tetrahedra() {
    let dir = temp_dir("medit");
    let text = "MeshVersionFormatted 2\nDimension\n3\n# a comment\nVertices\n4\n\
        0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n\
        Triangles\n1\n1 2 3 7\n\
        Tetrahedra\n1\n1 2 3 4 0\nEnd\n";
    std::fs::write(dir.join("tet.mesh"), text).unwrap();
    let loaded = load_volume_file(&dir.join("tet.mesh")).unwrap();
    assert_eq!(
        (
            loaded.mesh.nodes.len(),
            loaded.mesh.tets.len(),
            loaded.reoriented
        ),
        (4, 1, 0)
    );
    assert!((loaded.mesh.volume() - 1.0 / 6.0).abs() < 1e-15);
    let v = ShapeDesc::mesh_file("tet.mesh")
        .volume(&ShapeContext::new(&dir))
        .unwrap();
    assert_eq!(v, loaded.mesh);
    let bad = text.replace("1 2 3 4 0", "1 2 3 5 0");
    std::fs::write(dir.join("bad.mesh"), bad).unwrap();
    let err = load_volume_file(&dir.join("bad.mesh"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(
        err.contains("bad.mesh:16:") && err.contains("vertex 5"),
        "{err}"
    );
    let flat = text.replace("0 0 1 1\n", "0.5 0.5 0 1\n");
    std::fs::write(dir.join("flat.mesh"), flat).unwrap();
    let err = load_volume_file(&dir.join("flat.mesh"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(err.contains("degenerate"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn truncated_and_corrupted_files_never_panic() {
    let dir = temp_dir("fuzz");
    let medit =
        "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n\
        Tetrahedra\n1\n1 2 3 4 0\nEnd\n";
    let mut stl = String::from("solid t\n");
    for f in FACES {
        stl.push_str("facet normal 0 0 0\nouter loop\n");
        for &v in &f {
            let p = tet_corners()[v];
            stl.push_str(&format!("vertex {} {} {}\n", p[0], p[1], p[2]));
        }
        stl.push_str("endloop\nendfacet\n");
    }
    let mut outcomes = [0usize; 2];
    for (name, text) in [
        ("f.obj", CUBE_OBJ),
        ("f.msh", MSH),
        ("f.mesh", medit),
        ("f.stl", stl.as_str()),
    ] {
        let path = dir.join(name);
        let bytes = text.as_bytes();
        for cut in (0..bytes.len()).step_by(3) {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let ok = if name.ends_with(".obj") || name.ends_with(".stl") {
                load_surface_file(&path).is_ok()
            } else {
                load_volume_file(&path).is_ok()
            };
            outcomes[usize::from(ok)] += 1;
            // Flip one byte too.
            let mut corrupt = bytes.to_vec();
            corrupt[cut] = corrupt[cut].wrapping_add(7);
            std::fs::write(&path, &corrupt).unwrap();
            let _ = load_any_surface(&path);
        }
    }
    println!(
        "truncated files: {} rejected, {} still valid",
        outcomes[0], outcomes[1]
    );
    assert!(outcomes[0] > 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn paths_are_confined_and_missing_files_named() {
    let root = temp_dir("paths");
    let scene = root.join("scenes").join("place");
    let assets = root.join("assets");
    std::fs::create_dir_all(&scene).unwrap();
    std::fs::create_dir_all(assets.join("meshes")).unwrap();
    std::fs::write(root.join("secret.obj"), CUBE_OBJ).unwrap();
    std::fs::write(assets.join("meshes").join("cube.obj"), CUBE_OBJ).unwrap();
    std::fs::write(scene.join("local.obj"), CUBE_OBJ).unwrap();
    let roots = [assets.clone()];
    let ctx = ShapeContext {
        base_dir: &scene,
        asset_roots: &roots,
        generators: None,
    };
    assert!(resolve_mesh_path(&ctx, "local.obj").is_ok());
    // Reaching an asset root through `..` is allowed, and so is a path relative to an asset root.
    assert!(resolve_mesh_path(&ctx, "../../assets/meshes/cube.obj").is_ok());
    assert!(resolve_mesh_path(&ctx, "meshes/cube.obj").is_ok());
    let err = resolve_mesh_path(&ctx, "../../secret.obj").unwrap_err();
    println!("{err}");
    assert!(matches!(err, ShapeError::PathEscape { .. }), "{err:?}");
    let abs = root.join("secret.obj");
    assert!(matches!(
        resolve_mesh_path(&ctx, abs.to_str().unwrap()),
        Err(ShapeError::PathEscape { .. })
    ));
    let err = ShapeDesc::mesh_file("../../../../../../../../etc/passwd.obj")
        .surface(&ctx)
        .unwrap_err();
    println!("{err}");
    let err = ShapeDesc::mesh_file("meshes/missing.obj")
        .surface(&ctx)
        .unwrap_err();
    println!("{err}");
    let text = err.to_string();
    assert!(
        text.contains("missing.obj") && text.contains(&scene.display().to_string()),
        "{text}"
    );
    assert!(text.contains(&assets.display().to_string()), "{text}");
    let _ = std::fs::remove_dir_all(&root);
}
