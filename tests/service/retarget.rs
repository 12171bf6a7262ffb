//! Issue 52: `skeleton=` puts a take on another skeleton. The source's bones are read from
//! its own file and the answer's from the BVH the service wrote, both by the independent
//! `scripts/bvh-fk.py`, never by the service's own forward kinematics.

use crate::common;

use mocapstore::corpus;
use nalgebra::Vector3;
use serde_json::Value;

fn point(v: &Value) -> Vector3<f64> {
    Vector3::new(
        v[0].as_f64().unwrap(),
        v[1].as_f64().unwrap(),
        v[2].as_f64().unwrap(),
    )
}

/// Bones (parent, child) named alike in CMU's files and on Mixamo's rig (there under
/// `mixamorig:`).
const BONES: &[(&str, &str)] = &[
    ("LeftArm", "LeftForeArm"),
    ("LeftForeArm", "LeftHand"),
    ("RightArm", "RightForeArm"),
    ("LeftUpLeg", "LeftLeg"),
    ("LeftLeg", "LeftFoot"),
    ("RightLeg", "RightFoot"),
    ("RightFoot", "RightToeBase"),
    ("Neck", "Head"),
];

/// A CMU walk as BVH on Mixamo's rig: its bones point where the source file's do in every
/// frame, its feet stay under its head, it keeps the take's frames and rate, and it is in
/// metres (the rig's unit). Asked of another take's skeleton (`take:ID`), a Bandai one, it
/// answers on Bandai's joints. What cannot be answered says why.
#[tokio::test(flavor = "multi_thread")]
async fn a_cmu_walk_on_mixamos_rig_moves_its_bones_as_the_source_does() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let path = root.join("bvh/cmu/01_01.bvh");
    // Kept exactly, so that what is measured is the retargeting alone.
    let (status, report) = srv
        .post(
            "name=walk&codec=bvh-lossless",
            std::fs::read(&path).unwrap(),
        )
        .await;
    assert_eq!(status, 201, "{report}");
    let id = report["id"].as_str().unwrap().to_string();
    let (status, headers, bvh) = srv
        .get(&format!("/v1/takes/{id}/frames?format=bvh&skeleton=mixamo"))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&bvh));
    assert_eq!(headers["x-metres-per-unit"], "1");
    let dir = std::env::temp_dir().join(format!("mocapstore-retarget-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("on-mixamo.bvh");
    std::fs::write(&file, &bvh).unwrap();
    let source = common::script(&python, "bvh-fk.py", [&path]);
    let out = common::script(&python, "bvh-fk.py", [&file]);
    let (sn, on) = (
        common::strings(&source["names"]),
        common::strings(&out["names"]),
    );
    assert!(on.contains(&"mixamorig:Hips") && !on.contains(&"LowerBack"));
    let (sp, op) = (
        source["positions"].as_array().unwrap(),
        out["positions"].as_array().unwrap(),
    );
    assert_eq!(sp.len(), op.len(), "frames");
    assert_eq!(source["frame_time"], out["frame_time"]);
    let at = |names: &[&str], n: &str| {
        names
            .iter()
            .position(|m| *m == n)
            .unwrap_or_else(|| panic!("no joint {n}"))
    };
    let mut worst = 0.0f64;
    for (f, (a, b)) in sp.iter().zip(op).enumerate() {
        for (sa, sb) in BONES {
            let s = point(&a[at(&sn, sb)]) - point(&a[at(&sn, sa)]);
            let o = point(&b[at(&on, &format!("mixamorig:{sb}"))])
                - point(&b[at(&on, &format!("mixamorig:{sa}"))]);
            // CMU 01_01 is Y-up like the rig: no turn between their worlds.
            let angle = s.angle(&o).to_degrees();
            worst = worst.max(angle);
            assert!(angle < 1.0, "frame {f} {sa}→{sb}: {angle:.2}°");
        }
        let head = point(&b[at(&on, "mixamorig:Head")]);
        for foot in ["mixamorig:LeftFoot", "mixamorig:RightFoot"] {
            let foot = point(&b[at(&on, foot)]);
            assert!(head.y - foot.y > 1.0, "frame {f}: head {head}, foot {foot}");
        }
    }
    eprintln!(
        "CMU 01_01 on mixamo: worst bone {worst:.3}° over {} frames",
        sp.len()
    );

    // As positions of the rig's joints: the places the BVH answer's joints have.
    let (status, headers, json) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?format=json&skeleton=mixamo&t0=0&t1=1\
             &points=mixamorig:Head,mixamorig:LeftFoot"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&json));
    assert_eq!(headers["x-metres-per-unit"], "1");
    let v: Value = serde_json::from_slice(&json).unwrap();
    assert_eq!(
        v["points"],
        serde_json::json!(["mixamorig:Head", "mixamorig:LeftFoot"])
    );
    let frames = v["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 120);
    for (f, frame) in frames.iter().enumerate() {
        for (k, name) in ["mixamorig:Head", "mixamorig:LeftFoot"].iter().enumerate() {
            let want = point(&op[f][at(&on, name)]);
            let d = (point(&frame[k]) - want).norm();
            assert!(d < 1e-5, "frame {f} {name}: {d} m from the BVH answer's");
        }
    }

    // Another take's skeleton: a Bandai walk's.
    let bandai = root.join("bvh/bandai/dataset-1_walk_normal_001.bvh");
    let (status, report) = srv
        .post("name=bandai", std::fs::read(&bandai).unwrap())
        .await;
    assert_eq!(status, 201, "{report}");
    let other = report["id"].as_str().unwrap().to_string();
    let (status, _, on_bandai) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?format=bvh&skeleton=take:{other}&t0=0&t1=1"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&on_bandai));
    let text = String::from_utf8_lossy(&on_bandai);
    assert!(text.contains("ROOT joint_Root") && text.contains("UpperArm_L"));
    // And as glTF and FBX.
    for format in ["glb", "fbx"] {
        let (status, _, body) = srv
            .get(&format!(
                "/v1/takes/{id}/frames?format={format}&skeleton=smpl&t0=0&t1=1"
            ))
            .await;
        assert_eq!(status, 200, "{format}: {}", String::from_utf8_lossy(&body));
        assert!(body.windows(10).any(|w| w == b"left_elbow"), "{format}");
    }

    // Feet held: the same frames, the feet where the contacts left them.
    let (status, _, locked) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?format=bvh&skeleton=mixamo&feet=lock&t0=0&t1=2"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&locked));
    assert!(String::from_utf8_lossy(&locked).contains("Frames: 240"));

    // The map the answers used, from the take's stored skeleton.
    let (_, _, record) = srv.get(&format!("/v1/takes/{id}")).await;
    let record: Value = serde_json::from_slice(&record).unwrap();
    let skeleton = record["skeleton"].as_str().unwrap();
    let (status, map) = srv
        .get_json(&format!("/v1/skeletons/{skeleton}/map?to=mixamo"))
        .await;
    assert_eq!(status, 200, "{map}");
    assert_eq!(map["to"], "mixamo");
    let follows = |joint: &str| {
        map["joints"]
            .as_array()
            .unwrap()
            .iter()
            .find(|j| j["joint"] == joint)
            .map(|j| {
                (
                    j["follows"].as_str().unwrap().to_string(),
                    j["role"].clone(),
                )
            })
    };
    assert_eq!(
        follows("mixamorig:LeftArm"),
        Some(("LeftArm".into(), "left_shoulder".into()))
    );
    assert_eq!(
        follows("mixamorig:Spine2").map(|f| f.0),
        Some("Spine1".to_string()),
        "the chains' ends paired"
    );
    let unused = common::strings(&map["unused"]);
    assert!(
        unused.contains(&"LHipJoint") && unused.contains(&"Neck1"),
        "{unused:?}"
    );
    assert!(common::strings(&map["missing_roles"]).is_empty());
    assert!(map["shape_bones"]
        .as_array()
        .unwrap()
        .iter()
        .any(|b| b["from"] == "mixamorig:Hips" && b["to"] == "mixamorig:LeftUpLeg"));
    let scale = map["scale"].as_f64().unwrap();
    assert!((0.8..1.3).contains(&scale), "{scale}");
    for (query, status) in [("", 400), ("?to=nope", 400), ("?to=take:nope", 404)] {
        let (s, body) = srv
            .get_json(&format!("/v1/skeletons/{skeleton}/map{query}"))
            .await;
        assert_eq!(s, status, "{query}: {body}");
    }
    let (s, body) = srv.get_json("/v1/skeletons/abcdef/map?to=smpl").await;
    assert_eq!(s, 404, "{body}");

    // Refusals.
    for (query, status, says) in [
        ("format=bvh&skeleton=unreal", 400, "not a standard rig"),
        (
            "format=c3d&skeleton=mixamo",
            400,
            "C3D keeps the lab's markers",
        ),
        (
            "format=json&skeleton=mixamo&points=Head",
            400,
            "in the target skeleton; its 25 joints include mixamorig:Hips",
        ),
        ("format=bvh&skeleton=take:nope", 404, "nope"),
        // The format is told before the skeleton is looked for.
        (
            "format=c3d&skeleton=take:nope",
            400,
            "C3D keeps the lab's markers",
        ),
        ("format=bvh&feet=lock", 400, "give skeleton="),
        ("format=bvh&skeleton=smpl&feet=glue", 400, "free or lock"),
        ("format=bvh&skeleton=abcdef", 404, "skeleton abcdef"),
    ] {
        let (s, _, body) = srv.get(&format!("/v1/takes/{id}/frames?{query}")).await;
        let text = String::from_utf8_lossy(&body);
        assert_eq!(s, status, "{query}: {text}");
        assert!(text.contains(says), "{query}: {text}");
    }
    srv.stop().await;
    t.finish().await;
}

/// A token of one library cannot put a take on another library's take or on a skeleton
/// only that library's takes have: both are not found, as if they did not exist.
#[tokio::test(flavor = "multi_thread")]
async fn another_librarys_skeleton_is_not_found() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let reader = common::token(&t.store, "reader", "read", Some(&["lab"])).await;
    let admin = common::token(&t.store, "admin", "admin", None).await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let put = |path: &'static str, library: &'static str| {
        let (srv, admin, root) = (&srv, admin.clone(), root.clone());
        async move {
            let r = srv
                .client
                .post(format!("{}/v1/takes?library={library}", srv.base))
                .bearer_auth(&admin)
                .body(std::fs::read(root.join(path)).unwrap())
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 201);
            r.json::<Value>().await.unwrap()
        }
    };
    let walk = put("bvh/cmu/01_01.bvh", "lab").await["id"]
        .as_str()
        .unwrap()
        .to_string();
    let hidden = put("bvh/bandai/dataset-1_walk_normal_001.bvh", "secret").await;
    let hidden_id = hidden["id"].as_str().unwrap().to_string();
    let ask = |token: &str, query: &str| {
        let url = format!(
            "{}/v1/takes/{walk}/frames?format=bvh&t0=0&t1=1&{query}",
            srv.base
        );
        let (client, token) = (srv.client.clone(), token.to_string());
        async move {
            let r = client.get(url).bearer_auth(token).send().await.unwrap();
            (r.status().as_u16(), r.text().await.unwrap())
        }
    };
    let record: Value = srv
        .client
        .get(format!("{}/v1/takes/{hidden_id}", srv.base))
        .bearer_auth(&admin)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let skeleton = record["skeleton"].as_str().unwrap().to_string();
    for query in [
        format!("skeleton=take:{hidden_id}"),
        format!("skeleton={skeleton}"),
    ] {
        let (status, text) = ask(&reader, &query).await;
        assert_eq!(status, 404, "{query}: {text}");
        let (status, text) = ask(&admin, &query).await;
        assert_eq!(status, 200, "{query}: {text}");
        assert!(text.contains("UpperArm_L"), "{query}");
    }
    // An uploaded rig holds no library's motion: every reader may put takes on it.
    let ybot = std::fs::read(root.join("gltf/mixamo_ybot_character.glb")).unwrap();
    // (A small body: the scope is refused before the body is read, and a large one may
    // meet a closed connection while it is still being sent.)
    let (status, rig) = upload_rig(&srv, b"HIERARCHY".to_vec(), Some(&reader)).await;
    assert_eq!(status, 403, "a read token uploads nothing: {rig}");
    let (status, rig) = upload_rig(&srv, ybot, Some(&admin)).await;
    assert_eq!(status, 201, "{rig}");
    let id = rig["id"].as_str().unwrap();
    let r = srv
        .client
        .get(format!("{}/v1/skeletons/{id}", srv.base))
        .bearer_auth(&reader)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let (status, text) = ask(&reader, &format!("skeleton={id}")).await;
    assert_eq!(status, 200, "{text}");
    assert!(text.contains("mixamorig:LeftForeArm"));
    srv.stop().await;
    t.finish().await;
}

/// POST a rig file to `/v1/skeletons` (as `token`, if any): the status and the answer.
async fn upload_rig(srv: &common::Server, body: Vec<u8>, token: Option<&str>) -> (u16, Value) {
    let mut r = srv
        .client
        .post(format!("{}/v1/skeletons", srv.base))
        .body(body);
    if let Some(t) = token {
        r = r.bearer_auth(t);
    }
    let r = r.send().await.unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap_or(Value::Null))
}

/// The Mixamo Y Bot uploaded as a skeleton stands in its bind pose, and a CMU walk asked
/// of it as GLB is the Y Bot's own file playing the walk: its mesh and skin, its node
/// tree (the Armature that turns Blender's Z-up and scales centimetres), its joints
/// moving. Evaluated by pygltflib (scripts/gltf-eval.py), the character's bones point as
/// the source file's do (scripts/bvh-fk.py) in every frame and its head stays above its
/// feet; the Khronos validator finds no error in it. An FBX character's bones at their bind
/// pose are a rig too; a file that is no rig is a 400 saying why.
#[tokio::test(flavor = "multi_thread")]
async fn a_character_uploaded_plays_a_take_on_its_own_mesh() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let Some(python) = common::python() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 64 << 20).await;
    let ybot = std::fs::read(root.join("gltf/mixamo_ybot_character.glb")).unwrap();
    let (status, rig) = upload_rig(&srv, ybot.clone(), None).await;
    assert_eq!(status, 201, "{rig}");
    assert_eq!(rig["uploaded_as"], "glb");
    assert_eq!(rig["character"], true);
    assert_eq!(rig["joints"], 67);
    assert_eq!(rig["hierarchy"][0]["name"], "mixamorig:Hips");
    assert!(!rig["roles"].is_null(), "{rig}");
    let skeleton = rig["id"].as_str().unwrap().to_string();
    // The same file again is the same rig.
    let (status, again) = upload_rig(&srv, ybot, None).await;
    assert_eq!((status, &again["id"]), (200, &rig["id"]));

    let path = root.join("bvh/cmu/01_01.bvh");
    let (status, report) = srv
        .post(
            "name=walk&codec=bvh-lossless",
            std::fs::read(&path).unwrap(),
        )
        .await;
    assert_eq!(status, 201, "{report}");
    let id = report["id"].as_str().unwrap().to_string();
    let (status, _, glb) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?format=glb&skeleton={skeleton}&t0=0&t1=2"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&glb));
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let doc: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    assert_eq!(doc["meshes"].as_array().unwrap().len(), 2);
    assert_eq!(doc["skins"].as_array().unwrap().len(), 1);
    let dir = std::env::temp_dir().join(format!("mocapstore-character-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("walk-on-ybot.glb");
    std::fs::write(&file, &glb).unwrap();
    if let Some(m) = common::node_modules() {
        let v = common::validate(&m, &file);
        assert_eq!(v["errors"], 0, "{v}");
    }
    let source = common::script(&python, "bvh-fk.py", [&path]);
    let shown = common::script(&python, "gltf-eval.py", [&file]);
    let (sn, on) = (
        common::strings(&source["names"]),
        common::strings(&shown["nodes"]),
    );
    let (sp, op) = (
        source["positions"].as_array().unwrap(),
        shown["positions"].as_array().unwrap(),
    );
    assert_eq!(op.len(), 240, "the frames of 0 s to 2 s at 120 fps");
    let at = |names: &[&str], n: &str| {
        names
            .iter()
            .position(|m| *m == n)
            .unwrap_or_else(|| panic!("no joint {n}"))
    };
    let mut angles = Vec::new();
    for (f, (a, b)) in sp.iter().zip(op).enumerate() {
        for (sa, sb) in BONES {
            let s = point(&a[at(&sn, sb)]) - point(&a[at(&sn, sa)]);
            let o = point(&b[at(&on, &format!("mixamorig:{sb}"))])
                - point(&b[at(&on, &format!("mixamorig:{sa}"))]);
            let angle = s.angle(&o).to_degrees();
            assert!(angle < 1.0, "frame {f} {sa}→{sb}: {angle:.2}°");
            angles.push(angle);
        }
        let head = point(&b[at(&on, "mixamorig:Head")]);
        for foot in ["mixamorig:LeftFoot", "mixamorig:RightFoot"] {
            let foot = point(&b[at(&on, foot)]);
            assert!(head.y - foot.y > 0.8, "frame {f}: head {head}, foot {foot}");
        }
    }
    angles.sort_by(f64::total_cmp);
    eprintln!(
        "CMU 01_01 on the Y Bot (GLB, pygltflib): bone angle median {:.4}°, max {:.4}°",
        angles[angles.len() / 2],
        angles[angles.len() - 1]
    );
    // root=extract adds a joint the character's file does not have.
    let (status, _, body) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?format=glb&skeleton={skeleton}&root=extract&t0=0&t1=1"
        ))
        .await;
    assert_eq!(status, 400, "{}", String::from_utf8_lossy(&body));
    // The Y Bot's skeleton in other formats: its joints, no mesh.
    let (status, _, bvh) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?format=bvh&skeleton={skeleton}&t0=0&t1=1"
        ))
        .await;
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&bvh).contains("ROOT mixamorig:Hips"));

    // An FBX character: its skinned bones at their bind pose.
    let fbx = std::fs::read(root.join("fbx/mixamo_breathing_idle.fbx")).unwrap();
    let (status, rig) = upload_rig(&srv, fbx, None).await;
    assert_eq!(status, 201, "{rig}");
    assert_eq!(
        (&rig["uploaded_as"], &rig["character"]),
        (&"fbx".into(), &false.into())
    );
    let fbx_rig = rig["id"].as_str().unwrap();
    let (status, _, bvh) = srv
        .get(&format!(
            "/v1/takes/{id}/frames?format=bvh&skeleton={fbx_rig}&t0=0&t1=1"
        ))
        .await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&bvh));
    let on_fbx = dir.join("walk-on-fbx.bvh");
    std::fs::write(&on_fbx, &bvh).unwrap();
    let out = common::script(&python, "bvh-fk.py", [&on_fbx]);
    let on = common::strings(&out["names"]);
    let op = out["positions"].as_array().unwrap();
    // The bones whose joints bvh-fk.py names in both (it does not name End Sites).
    let bones: Vec<_> = BONES
        .iter()
        .filter(|(a, b)| {
            [a, b]
                .iter()
                .all(|n| on.contains(&format!("mixamorig:{n}").as_str()))
        })
        .collect();
    assert!(bones.len() >= 6, "{on:?}");
    for (f, (a, b)) in sp.iter().zip(op).enumerate() {
        for (sa, sb) in &bones {
            let s = point(&a[at(&sn, sb)]) - point(&a[at(&sn, sa)]);
            let o = point(&b[at(&on, &format!("mixamorig:{sb}"))])
                - point(&b[at(&on, &format!("mixamorig:{sa}"))]);
            let angle = s.angle(&o).to_degrees();
            assert!(angle < 1.0, "FBX rig frame {f} {sa}→{sb}: {angle:.2}°");
        }
    }

    // What is no rig says why.
    let c3d = std::fs::read(root.join("c3d/btkdata__PiG__PiG_Calibration3_FF.c3d")).ok();
    let skinless = br#"{"asset": {"version": "2.0"}, "nodes": [{"name": "a"}]}"#.to_vec();
    // A character whose buffer lies in another file cannot be written back: not kept.
    let elsewhere = serde_json::to_vec(&serde_json::json!({
        "asset": {"version": "2.0"},
        "nodes": [{"name": "hips", "children": [1]}, {"name": "head", "translation": [0, 1, 0]}],
        "skins": [{"joints": [0, 1]}],
        "buffers": [{"byteLength": 4, "uri": "mesh.bin"}]
    }))
    .unwrap();
    for (body, says) in [
        (skinless, "no skin"),
        (elsewhere, "another file"),
        (b"not a file".to_vec(), "not BVH"),
        (Vec::new(), "empty"),
    ]
    .into_iter()
    .chain(c3d.map(|b| (b, "a rig comes from")))
    {
        let (status, e) = upload_rig(&srv, body, None).await;
        // 400 for what is no rig file; 422 for a file of a rig format that does not read
        // as one (as a take that does not parse).
        assert!([400, 422].contains(&status), "{status} {e}");
        assert!(e["error"].to_string().contains(says), "{says}: {e}");
    }
    std::fs::remove_dir_all(&dir).ok();
    srv.stop().await;
    t.finish().await;
}
