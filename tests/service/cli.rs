//! The `mocapstore` binary as a user runs it.

use crate::common;

use mocapstore::corpus;

use common::mocapstore;

fn corpus_file(rel: &str) -> String {
    corpus::root().join(rel).display().to_string()
}

#[test]
fn inspect_reports_counts_units_and_failures() {
    if corpus::for_tests().is_none() {
        return;
    }
    let bvh = corpus_file("bvh/cmu/01_01.bvh");
    let (ok, out, _) = mocapstore(&["inspect", "--json", &bvh]);
    assert!(ok);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["frames"], 2752);
    assert_eq!(v["skeleton_joints"], 31);
    assert_eq!(v["unit"], "cmu");
    assert_eq!(v["unit_inferred"], true);

    let empty = corpus_file("trc/TRCSamples__Empty.trc");
    let (ok, out, err) = mocapstore(&["inspect", &bvh, &empty]);
    assert!(!ok, "a failed file makes the exit status non-zero");
    assert!(out.contains("01_01.bvh"), "{out}");
    assert!(
        err.contains("TRCSamples__Empty.trc") && err.contains("empty"),
        "{err}"
    );
}

#[test]
fn convert_round_trips_and_explains_errors() {
    if corpus::for_tests().is_none() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("mocapstore-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let c3d = corpus_file("c3d/btkdata__others__Gait.c3d");
    let json = dir.join("gait.json").display().to_string();
    let (ok, _, err) = mocapstore(&["convert", &c3d, &json]);
    assert!(ok, "{err}");
    let (ok, out, _) = mocapstore(&["inspect", "--json", &json]);
    assert!(ok);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(
        (v["points"].as_u64(), v["frames"].as_u64()),
        (Some(33), Some(487))
    );
    assert_eq!(v["unit"], "mm");

    // Point data cannot become BVH; the message says why and nothing is left behind.
    let bvh = dir.join("gait.bvh");
    let (ok, _, err) = mocapstore(&["convert", &c3d, &bvh.display().to_string()]);
    assert!(!ok);
    assert!(err.contains("skeleton"), "{err}");
    assert!(!bvh.exists());

    let (ok, _, err) = mocapstore(&["convert", &c3d, "out.xyz"]);
    assert!(!ok && err.contains("--to"), "{err}");
    let (ok, _, err) = mocapstore(&["convert", &c3d, &json, "--unit", "furlong"]);
    assert!(!ok && err.contains("furlong"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[tokio::test]
async fn ingest_uploads_a_folder_and_lists_failures() {
    if corpus::for_tests().is_none() {
        return;
    }
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let base = srv.base.clone();
    let trc = corpus::root().join("trc").display().to_string();
    let out = common::mocapstore_beside(
        [
            "ingest",
            &trc,
            "--server",
            &base,
            "--library",
            "trc",
            "--max-error-mm",
            "2",
        ]
        .map(String::from)
        .to_vec(),
    )
    .await;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    // Empty.trc and Truncated.trc cannot be read; the other 11 store.
    assert!(
        !out.status.success(),
        "a failed file makes the exit status non-zero"
    );
    assert!(stdout.contains("11 stored, 2 failed"), "{stdout}");
    assert!(
        stderr.contains("TRCSamples__Empty.trc") && stderr.contains("TRCSamples__Truncated.trc"),
        "{stderr}"
    );
    assert_eq!(t.store.count().await.unwrap(), 11);
    srv.stop().await;
    t.finish().await;
}

/// A dataset folder as it is published (Bandai Namco's: a label `.json` beside each take,
/// a readme, a script, a hidden file): the takes are stored, everything else is skipped and
/// counted once, and the exit status is zero.
#[tokio::test]
async fn ingest_passes_a_dataset_folder_with_label_files() {
    let Some((root, _)) = corpus::for_tests() else {
        return;
    };
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let dir = std::env::temp_dir().join(format!("mocapstore-dataset-{}", uuid::Uuid::now_v7()));
    std::fs::create_dir_all(dir.join("data")).unwrap();
    std::fs::create_dir_all(dir.join("utils")).unwrap();
    let takes = [
        "dataset-1_walk_normal_001",
        "dataset-1_bow_active_001",
        "dataset-1_dance-short_normal_001",
    ];
    for (k, name) in takes.iter().enumerate() {
        let bvh = root.join("bvh/bandai").join(format!("{name}.bvh"));
        std::fs::copy(&bvh, dir.join("data").join(format!("{name}.bvh"))).unwrap();
        let labels = format!("{{\"content\": {k}, \"style\": 0}}");
        std::fs::write(dir.join("data").join(format!("{name}.json")), labels).unwrap();
    }
    std::fs::write(dir.join("README.md"), "# a dataset\n").unwrap();
    std::fs::write(dir.join("utils/convert.py"), "print('hi')\n").unwrap();
    std::fs::write(dir.join("data/.DS_Store"), [0u8, 1, 2]).unwrap();
    let (base, path) = (srv.base.clone(), dir.display().to_string());
    let out = common::mocapstore_beside(
        ["ingest", &path, "--server", &base, "--library", "bandai"]
            .map(String::from)
            .to_vec(),
    )
    .await;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains(
            "3 stored, 0 failed, 5 skipped (3 beside takes with their names, 2 other files"
        ),
        "{stdout}"
    );
    assert!(stdout.contains("README.md: not motion"), "{stdout}");
    assert_eq!(t.store.count().await.unwrap(), 3);
    std::fs::remove_dir_all(&dir).unwrap();
    srv.stop().await;
    t.finish().await;
}

/// The Bandai Namco folder as a dataset publishes it, a label file beside each BVH (JSON
/// or YAML, written here from the dataset's own naming): every take is stored with its
/// labels, none fails; read again by `--labels-from-name`, the same content and style. All
/// 174 takes (quant: two seconds). A label file that holds no labels fails its take, named.
#[tokio::test(flavor = "multi_thread")]
async fn a_dataset_folder_is_labelled_by_its_sidecars_and_its_names() {
    let Some((root, entries)) = corpus::for_tests() else {
        return;
    };
    let mut names: Vec<String> = entries
        .iter()
        .filter_map(|e| e.path.strip_prefix("bvh/bandai/"))
        .filter_map(|p| p.strip_suffix(".bvh"))
        .map(str::to_string)
        .collect();
    names.sort();
    assert_eq!(names.len(), 174);
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let dir = std::env::temp_dir().join(format!("mocapstore-labels-{}", uuid::Uuid::now_v7()));
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    // dataset-1_walk_normal_001: content walk, style normal.
    let split = |n: &str| -> (String, String) {
        let p: Vec<&str> = n.split('_').collect();
        (p[1].to_string(), p[2].to_string())
    };
    for (i, name) in names.iter().enumerate() {
        std::fs::copy(
            root.join("bvh/bandai").join(format!("{name}.bvh")),
            data.join(format!("{name}.bvh")),
        )
        .unwrap();
        let (content, style) = split(name);
        if i % 2 == 0 {
            let json = serde_json::json!({"content": content, "style": style});
            std::fs::write(data.join(format!("{name}.json")), json.to_string()).unwrap();
        } else {
            let yaml = format!("content: {content}\nstyle: {style}\n");
            std::fs::write(data.join(format!("{name}.yaml")), yaml).unwrap();
        }
    }
    let run = |extra: &[&str]| {
        let mut args: Vec<String> = vec![
            "ingest".into(),
            data.display().to_string(),
            "--server".into(),
            srv.base.clone(),
            "--codec".into(),
            "quant".into(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        common::mocapstore_beside(args)
    };
    let out = run(&["--library", "sidecars"]).await;
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let n = names.len();
    assert!(
        stdout.contains(&format!("{n} stored, 0 failed")),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!("{n} takes labelled from the files beside them")),
        "{stdout}"
    );
    let pattern = "{dataset}_{content}_{style}_{n}";
    let out = run(&[
        "--library",
        "names",
        "--no-sidecar-labels",
        "--labels-from-name",
        pattern,
    ])
    .await;
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(!stdout.contains("do not fit"), "{stdout}");

    let server = &srv;
    let listed = |library: &str, filter: &str| {
        let path = format!("/v1/takes?library={library}&limit=500{filter}");
        async move {
            let (status, page) = server.get_json(&path).await;
            assert_eq!(status, 200, "{page}");
            page["items"].as_array().unwrap().clone()
        }
    };
    let from_sidecars = listed("sidecars", "").await;
    let from_names = listed("names", "").await;
    assert_eq!((from_sidecars.len(), from_names.len()), (n, n));
    for take in &from_sidecars {
        let name = take["name"].as_str().unwrap();
        let (content, style) = split(name);
        assert_eq!(
            take["labels"],
            serde_json::json!({"content": content, "style": style}),
            "{name}"
        );
        let same = from_names.iter().find(|t| t["name"] == name).unwrap();
        let l = &same["labels"];
        assert_eq!(
            (&l["content"], &l["style"]),
            (&take["labels"]["content"], &take["labels"]["style"]),
            "{name}"
        );
        assert_eq!(l["dataset"], "dataset-1", "{name}");
        assert!(l["n"].is_number(), "{name}: {l}");
    }
    // Found by their labels.
    let walks = names.iter().filter(|n| split(n).0 == "walk").count();
    assert!(walks > 0);
    assert_eq!(listed("sidecars", "&label.content=walk").await.len(), walks);
    assert_eq!(
        listed("names", "&label.content=walk&label.dataset=dataset-1")
            .await
            .len(),
        walks
    );
    let firsts = names.iter().filter(|n| n.ends_with("_001")).count();
    assert!(firsts > 0);
    assert_eq!(listed("names", "&label.n=1").await.len(), firsts);
    assert_eq!(
        listed("names", "&label.n=01").await.len(),
        firsts,
        "numbers by value"
    );
    assert!(listed("sidecars", "&label.content=nothing")
        .await
        .is_empty());

    // The same folder as a ZIP (as a dataset is downloaded, with macOS's shadow entries
    // and a readme): read entry by entry, the same takes and labels.
    let zipped = dir.join("dataset.zip");
    {
        use std::io::Write;
        let mut z = zip::ZipWriter::new(std::fs::File::create(&zipped).unwrap());
        let opts = zip::write::SimpleFileOptions::default();
        let mut files: Vec<_> = std::fs::read_dir(&data)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        for f in &files {
            let name = f.file_name().unwrap().to_string_lossy().into_owned();
            z.start_file(format!("data/{name}"), opts).unwrap();
            z.write_all(&std::fs::read(f).unwrap()).unwrap();
        }
        z.start_file("__MACOSX/data/._x.bvh", opts).unwrap();
        z.write_all(b"\0\x05\x16\x07").unwrap();
        z.start_file("README.txt", opts).unwrap();
        z.write_all(b"a dataset").unwrap();
        z.finish().unwrap();
    }
    let out = common::mocapstore_beside(
        [
            "ingest",
            &zipped.display().to_string(),
            "--server",
            &srv.base,
            "--codec",
            "quant",
            "--library",
            "zipped",
        ]
        .map(String::from)
        .to_vec(),
    )
    .await;
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains(&format!(
            "{n} stored, 0 failed, {} skipped ({n} beside takes with their names, 1 other",
            n + 1
        )),
        "{stdout}"
    );
    let from_zip = listed("zipped", "").await;
    assert_eq!(from_zip.len(), n);
    for take in &from_zip {
        let same = from_sidecars
            .iter()
            .find(|t| t["name"] == take["name"])
            .unwrap();
        assert_eq!(take["labels"], same["labels"]);
        assert_eq!(take["frames"], same["frames"]);
    }

    // A label file that holds no labels: its take fails, named with it, and is not stored.
    let bad = dir.join("bad");
    std::fs::create_dir_all(&bad).unwrap();
    std::fs::copy(data.join(format!("{}.bvh", names[0])), bad.join("take.bvh")).unwrap();
    std::fs::write(bad.join("take.json"), r#"{"content": [1, 2]}"#).unwrap();
    let before = t.store.count().await.unwrap();
    let out = common::mocapstore_beside(
        ["ingest", &bad.display().to_string(), "--server", &srv.base]
            .map(String::from)
            .to_vec(),
    )
    .await;
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("take.json") && stderr.contains("list"),
        "{stderr}"
    );
    assert_eq!(t.store.count().await.unwrap(), before);
    std::fs::remove_dir_all(&dir).unwrap();
    srv.stop().await;
    t.finish().await;
}

/// `mocapstore fetch` writes a range of a take to a file in its extension's format: a BVH
/// take's rows as uploaded; a take without its animation is refused, naming the reason.
#[tokio::test]
async fn fetch_writes_a_range_as_bvh_and_explains_a_refusal() {
    let t = common::sqlite().await;
    let srv = common::start(t.store.clone(), 8 << 20).await;
    let text = mocapstore::motion::synthetic::dancer_bvh(300, 120.0, 4, 4);
    let (status, report) = srv
        .post("codec=bvh-lossless", text.as_bytes().to_vec())
        .await;
    assert_eq!(status, 201, "{report}");
    let id = report["id"].as_str().unwrap().to_string();
    let (status, report) = srv.post("codec=quant", text.as_bytes().to_vec()).await;
    assert_eq!(status, 201, "{report}");
    let quant = report["id"].as_str().unwrap().to_string();
    let dir = std::env::temp_dir().join(format!("mocapstore-fetch-{}", uuid::Uuid::now_v7()));
    std::fs::create_dir_all(&dir).unwrap();
    let (base, out) = (srv.base.clone(), dir.join("part.bvh"));
    let run = common::mocapstore_beside;
    let o = run(vec![
        "fetch".into(),
        id.clone(),
        out.display().to_string(),
        "--server".into(),
        base.clone(),
        "--start".into(),
        "100".into(),
        "--end".into(),
        "160".into(),
    ])
    .await;
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = |s: &str| -> Vec<String> {
        let at = s.find("Frame Time").unwrap();
        s[at..].lines().skip(1).map(str::to_string).collect()
    };
    let written = std::fs::read_to_string(&out).unwrap();
    assert_eq!(rows(&written), rows(&text)[100..160]);
    let o = run(vec![
        "fetch".into(),
        quant,
        dir.join("q.bvh").display().to_string(),
        "--server".into(),
        base,
    ])
    .await;
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("keeps joint positions only"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
    srv.stop().await;
    t.finish().await;
}
