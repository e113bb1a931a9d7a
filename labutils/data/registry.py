"""The data sets' registry: every file of every data set, pinned by its size and sha256, with where to get it.

The checksums were taken from copies made unchanged from the sources listed here (each set's ``SOURCE.md`` in the
shared data folder records where from). Each set names its sources in order: the **origin** where one still serves
these exact bytes, then a **mirror** (a public copy of the same bytes) where the origin is gone, serves another
packaging, or fails. :mod:`labutils.data.fetch` downloads them; :func:`status` says what is on the data path.

The registry, :data:`DATASETS`, maps each name (the folder name on the data path) to its :class:`DataSet`:

>>> list(DATASETS)
['dino', 'fountain-P11', 'templeRing', 'chessboard', 'bal']
>>> f = DATASETS["bal"].files[0]; f.path, f.size
('problem-49-7776-pre.txt', 1785529)
>>> [s.role for s in DATASETS["templeRing"].sources]
['origin', 'mirror']
>>> sum(ds.n_bytes for ds in DATASETS.values())
72857186
"""
from dataclasses import dataclass, field
from pathlib import Path

import pooch

from .paths import data_dirs


@dataclass(frozen=True)
class DataFile:
    """One file of a data set: its path inside the set's folder ('/'-separated), size in bytes and sha256."""

    path: str
    size: int
    sha256: str


@dataclass(frozen=True)
class Source:
    """A place a data set's files can be downloaded from.

    Attributes
    ----------
    kind : {'files', 'bz2', 'zip'}
        ``'files'``: each file at ``url/<path>``; ``'bz2'``: each file bzip2-compressed at ``url/<path>.bz2``;
        ``'zip'``: one zip archive at ``url`` holding each file as ``member_prefix + <path>``.
    url : str
    role : str
        ``'origin'``, ``'mirror'``, or the environment variable that set it.
    member_prefix : str
        For ``'zip'``: the folder inside the archive.

    >>> Source("bz2", "https://example.org/ladybug", "origin").url_of("problem.txt")
    'https://example.org/ladybug/problem.txt.bz2'
    >>> Source("zip", "https://example.org/t.zip", "origin", "templeRing/").url_of("README.txt")
    'https://example.org/t.zip (templeRing/README.txt)'
    """

    kind: str
    url: str
    role: str
    member_prefix: str = ""

    def url_of(self, path: str) -> str:
        """Where ``path`` comes from (for a zip: the archive and the member)."""
        if self.kind == "files":
            return f"{self.url}/{path}"
        if self.kind == "bz2":
            return f"{self.url}/{path}.bz2"
        return f"{self.url} ({self.member_prefix}{path})"


@dataclass(frozen=True)
class DataSet:
    """A data set: what it is, who to cite, where to get it, and its files.

    Attributes
    ----------
    name : str
        Also the folder name on the data path.
    title, origin, licence, citation : str
        What it is; the page that publishes it; the licence as stated (or that none is); what to cite.
    sources : tuple of Source
        Tried in order; empty when no public download of these files is known (then ``note`` says why).
    files : tuple of DataFile
    note : str
    """

    name: str
    title: str
    origin: str
    licence: str
    citation: str
    sources: tuple
    files: tuple = field(repr=False)
    note: str = ""

    @property
    def n_bytes(self) -> int:
        """Total size of the files, bytes."""
        return sum(f.size for f in self.files)


class FetchError(Exception):
    """A data set could not be laid out; ``str()`` is one line naming the file: ``'<path>: <what went wrong>'``.

    ``unresolved`` is True when the download failed because no host name resolved (offline, most likely).
    """

    def __init__(self, path, message, *, unresolved=False):
        super().__init__(f"{path}: {message}")
        self.path, self.message, self.unresolved = path, message, unresolved


def _parse(table):
    rows = [line.split() for line in table.strip().splitlines()]
    return tuple(DataFile(path, int(size), sha) for path, size, sha in rows)


_GITHUB = "https://raw.githubusercontent.com"

# path  size  sha256, per set (computed from the shared copies; equal to each SOURCE.md's table)
_TABLES = {
    "dino": """
BAdino2.mat 289225 28bed45c3bfe7a13f9618a8ffea7fc640a9c716af0133aee72f3a94286badcc7
images/viff.000.png 722038 5eb7d591c0a69d64786b52bf78e02ee6cd9162d4ca07a6bc1051adf3469cd890
images/viff.001.png 722786 4cf93ff12c87b4445fde56db7ccac0693eabaeb23a7da05fa29bc1d34935ddfd
images/viff.002.png 722591 ae4d598f331e24c98fc99c59e490ace8e184a477316941cef769f8d511e81c35
images/viff.003.png 721328 c4dba42a07e617819a09a4ba592372702e4e9b07eb61a466ad79ed1b7266ce12
images/viff.004.png 716476 e2ed01cbd156d1856ab60740c3fee0aed86088ac9689e109cfe41eda94f974f0
images/viff.005.png 710996 8437792c569c9b11a4712cdeb2fe8588ac4009673898addbb58a9505a26b2a6d
images/viff.006.png 704986 ab0150620999415bdee97865055b04b3ad58afcfce7e4fce0e0de4a32c444b18
images/viff.007.png 697654 a9006517ce0aeeb31c28fe5bafe5476235c0628868d0a8f0df18346086051028
images/viff.008.png 693178 86771beaa964738b8d0703b5d5cb39550cca33f1550c8e29b140a8de0c20bea1
images/viff.009.png 690624 3f4e7604053b626b551e9b79cca40a64aa4e1a6fc9a0032ed71980b7ed281fb7
images/viff.010.png 685195 545db33f1944cbc4aeaff1412a16f9c86ef8a60fe09768e667addb7fcd138ee9
images/viff.011.png 685998 fca7f0c2164957fd3fd5d4c5b8b799e16e68cc09e3285db3c0e94db91f4ae2dc
images/viff.012.png 685724 472cbd341d087e9dff3d035269eb293c7c972845cf6cc8b56e5bf1f6954cbf24
images/viff.013.png 684218 66149b008a314d2bd83c7c558384b6b6e3fd7a1ceb3d42c831b1f5f0a3d73f47
images/viff.014.png 687278 f9ac1deb13519cb915eb430a2def8acdce14606fa06802c331f5c8e4c052d26e
images/viff.015.png 692264 8fc56e9663ac6603ee3c93fe12fb971f43f89546986cb387423ae971afd7374a
images/viff.016.png 696995 3bddaea1e0038f490f5e93f3d2d1cddf0d4bf8d5d85eae31b7d43a86ba3366fc
images/viff.017.png 703662 7d50e58266231a91435954649005eb84f80099c435b62b5ca13623e0eb27a13d
images/viff.018.png 708468 4ba86ac4d15c1e5f8892117f6498715a2f0264c9447946eae9004e0527a066f1
images/viff.019.png 709247 c556cbfacf7c52d7b2fd7623eb267e89368337640782bfa69492966ee3347a69
images/viff.020.png 710662 94192025c7d2051b427134dbfe022b3583dc9e37999b058a065493dba957583b
images/viff.021.png 710825 cb4ae665507e759249c7c057e1b22d64912447c8878ff4a45717cb2f0397bf1c
images/viff.022.png 711079 f3f0bba62dba8f2c49f05f16c22dad9be5f565eea12b34ac66026ecbda91e4ac
images/viff.023.png 710548 926cab745f3810fb4c2a513333aadd80e7e4334ae5660fa4bb5e6efb3f25be6a
images/viff.024.png 708280 58faa6f50d38eefcb31482ec075a50c1a3f1e60ec48c39932f315b8057e405d2
images/viff.025.png 705761 05a7600cafe3a27dd5d3c90ae702844700ca43a6ae97917ac787538eedba6c37
images/viff.026.png 705173 0a08a23231a6245331b2ac63e08687f33a938defca0a7d26a9568ea4f2661fda
images/viff.027.png 707948 d077b2213f0090a1cc91788f298aa563dbd67187d14257e5290bd3c74f59e25c
images/viff.028.png 708269 cc1ab120b6ca3c87755e931685db9d5266b34726f0b1232c19865fbf73242586
images/viff.029.png 706487 383d421fb7bc5cee433ae27f6573350df56bebdc0db78ab15d92f64a2ae9d5e9
images/viff.030.png 705270 9f5079cdba3e8aaf4d9c77eeaaff26905e666d8d92f0238d5201ac2d40f83557
images/viff.031.png 704899 e1403b0de0473d354aeb1dcb621b8e0dbd7f87f97a63eedac1fc702010b6e082
images/viff.032.png 707126 a153b80cabf992f0a65a3a9f9bfc58bb23274dd253da2a4f8d3b38daddf3e0a7
images/viff.033.png 709992 248a49df06a05a7063b3fc66ef1bda4db81a03d611cc9d1969872b8c99b7ee23
images/viff.034.png 715324 5a934d85371a3892da8b5f986508c169f2c9a5e6f08c389ac4df6eca42888f31
images/viff.035.png 720390 f8333290dbc5d7992a5a98e272619ebadf6fe85553520f9c7b35bcfdc8095510
""",
    "fountain-P11": """
gt_dense_cameras/0000.jpg.camera 183 ecf7d87adb058729193d1d658181fb91007c309b28222ef14538ea6edf6e3b51
gt_dense_cameras/0001.jpg.camera 183 741c418a0a8c5652724761bb6eb18ffec45fd500ebd9ea95b889085195e26fa2
gt_dense_cameras/0002.jpg.camera 180 1b4c9a8725f600f587d0a850907797bb5693da0bfaeb01da90bbfb114907c590
gt_dense_cameras/0003.jpg.camera 184 882dd2ad95aef47b5d5150f74b7d6adffe7ce9718e8700755e04f1e4c2b4291b
gt_dense_cameras/0004.jpg.camera 184 5d91d297976ae000b3c91808c64df90ca9612919839cf63f4b8dd12ef4990c4e
gt_dense_cameras/0005.jpg.camera 185 33e3c6a26540b8c42611cd5e4b78dd2f15ef4d1611eb156c888583d04a4045c4
gt_dense_cameras/0006.jpg.camera 186 dfa3f23eb4079f2aac81fcf1e313f10f0c5f8afab3c9ee6ef3fa8ead00e0aade
gt_dense_cameras/0007.jpg.camera 182 2103aea75d61d7a977b55c36e09bed2af729b7ada2a963e94a37358574b926a2
gt_dense_cameras/0008.jpg.camera 186 d1ebbe60304b439d687cb97aad74a306a632ca0605e7052d7a2b52542b295846
gt_dense_cameras/0009.jpg.camera 182 b286a42c394537604f99d587b154a2b80f78300b1835c27bd7bbe0d73f691f88
gt_dense_cameras/0010.jpg.camera 181 cac077afad3f72f73fb21ea6fbcf639ca6a950a2ea2919f55471326411e2cc0a
images/0000.jpg 2829295 dba9a66d5f9fa9d8d6a9fe2646b5107c004f5ad5dd99088eab1f27a661415f91
images/0001.jpg 2932298 3fdd650afdd58eb846255e2b3dace394ecc1d9d46a6ed7a9100f5946b8db99b6
images/0002.jpg 2961594 23f39e085c4d6537849bea22e1082343bf81631fddfbebf707433335d0c64741
images/0003.jpg 3030989 e9694c307343c609e6d8e311bdb0e1d010b4d4482c32e2a5e557535d9194b8c8
images/0004.jpg 3036204 e16a6928525bb25b89641d7866f946ab2348a58138c6b5c6074ff1f2285b8297
images/0005.jpg 3024921 4eaf96a4c9bf128946dfb61744d440966ee220be179529a51925b343dfe17f64
images/0006.jpg 3039278 940af32ff053cb480f3038fdc6b2d1bfa3d3a589f1e08cd29bec736e84594a7f
images/0007.jpg 2973006 852317bdf8c1de049bddd5ad2baa035794f425e955a9e9e7f54ad9885d1b684e
images/0008.jpg 3008939 76374ad0a125d5657743463622ab48c892c96d59b353527477c2dc709b129795
images/0009.jpg 3057054 e69d2b5f718a8600020fa98c8f85b0a6bef540a015368509b1df06120a90a693
images/0010.jpg 3056872 d67a19187030bc48875b82be2610c8327fcf93d29713f62e7f744c074d6758dd
images/K.txt 46 820441d1ad0051e8b223e4b804c94b1296371fa03267020fd20c0ea5e520589c
""",
    "templeRing": """
README.txt 1715 ac5e863319aa127f0461dab927828ea5c9675378c911a4877e9ea1ff950323df
templeR0001.png 308597 46e0ead520a16673e32eb36734661b19281fb520e69ff77891216e6971cb9712
templeR0002.png 305810 33ce729cce35a50ebeefbd8c8ddaf3a58c7cd8e21e8168562e9987ad1dc0881b
templeR0003.png 296035 d7b61c4c76dfa619d15040a7f90957bf714fb75e398df925ba84e52f18b8a6a7
templeR0004.png 294679 d79d27c9491257f90978798584c9a4c3c257dd3dd2b8370ac064ca711d4172af
templeR0005.png 288839 aa5f6b4e0e5bd76044ee11f9793299ebe5d5177b65a8e79282d1e150f1fed6bb
templeR0006.png 192180 ee3d3d5efd3239d52422d6f0f4bb090a119f4b2c37e93e91872534a867ad7afc
templeR0007.png 173827 42c6254cba4987c4952144451d3b591b2a9b57617349530e54567accaecebe9f
templeR0008.png 158920 755d7fdb08feb7316b2eb1f994769fe7b7febcc43730bfd579a3c593e8ff0bd0
templeR0009.png 161764 f79fa50a893aba5850767a458b7d6d6a42e1cfa44182e98737b04f53dac23317
templeR0010.png 167079 76f15485ac8cbecf2029937f6e351c914be0604d17d6c76eecea31d6b8439dcf
templeR0011.png 173631 10a00da81bac60e4f27e55a1a1009b886f014c782f13365cce3107de07348e3e
templeR0012.png 182960 d7877932bbadacfb6fad0d904b1cf75f237219167295824a53397b0f5f6928c0
templeR0013.png 268493 5208c81b360d1fdd35b97d4a549c903833e8d47ee0f0815f54e4e15c6e6c0ad9
templeR0014.png 271763 02d30c75c9e7b4c6e3ed8cd1087585c94b5a2d1c46290fab93ffb7857f36e35b
templeR0015.png 268447 fad01a491c51f0a1dd52a70d5404c17106d07539132266c45f09d8c4fb25e69b
templeR0016.png 261776 8f8cee917bb7e2947b820ac5a3b7cf6abb39ee3dd1875756b895c8e741796a9a
templeR0017.png 260216 3309a3f42ceff74dd5495bdd07fe669d845259414a980d1260ef2e8742d562b4
templeR0018.png 228060 ffa9e6d19bc780139270315f4c5f673fa7e90497566b680f8fc878657931eec7
templeR0019.png 240678 fab6f8438c0399666f8f3cf2187d87b2f079b31cc1fb6c0acb1facfc8ee509f9
templeR0020.png 231247 51c75ba797dd82e3a0835c9b435b34fa1aa6c1f5fb8e895f57eebfcd845e2469
templeR0021.png 215296 1afdc580dd3fc0337b1a056066e952d92a78a2aaf0c2a2dc72c56fc259e95cf6
templeR0022.png 218692 0c841f27920ea7dbdd7788591c867e9bf59647aa5f338599f05a4398b76d2c56
templeR0023.png 225331 76e37ab9d82cfeeb6b73bab0ea1c78724e2e0955cb665878c12153285b0005a5
templeR0024.png 247005 9b474a1fa539adf06ec362a5e6554705be7cf2a48397f7ab4d8ccbe35dd41843
templeR0025.png 256024 ac92bfdbaac056b2496194bf534d910426e5dfecaacd0c78c465619aa631ac90
templeR0026.png 285040 920f1d978de6da8e75e86d2f98a228ec236fb38bfab0ddc84eabc841a7efca46
templeR0027.png 306318 4b02166d19734e4e1cb0b8d27b7a224ea0b40e2f92e57455b5dd979cb71c647b
templeR0028.png 308662 e18c19069c5fa5a49f710bdea040beb17cacb9b3221fc52340f8f9351414a60c
templeR0029.png 308537 f7c59a2cfaa22de8d43fd8680c686e43b337b5eb2b60addfeecc4619fa986b84
templeR0030.png 310559 e36c68e37eec5426aacddd3b879aa1116c25c8663a6c54654c60f362521b67fd
templeR0031.png 310103 6841898e5f538485fc15fc1f1bf7f66d64d1b40cdea8ea8554fec3329c7785f1
templeR0032.png 250616 48afe04d8f8543d9fe7f0e336c7dff5e04c08d41b64f1093326494f56561988d
templeR0033.png 251950 7c0eff3754d46b6cd583a1ff5d948c504734db3be1dec4cf1e5fea2d17035ff1
templeR0034.png 247797 51d21155a52e90a3904b3f8c8c07a6e45a3e4a029a60f78d732a7e4f5b99186c
templeR0035.png 242400 2e560251b3e79197f92fddba0fc14914385e93d276e55902fd155493b3209020
templeR0036.png 234309 071b03304add70838986fe130d2f5e368600234a7351eefbb38b9fd59b8d854c
templeR0037.png 223278 6e76cf8da0b19525f2d2e0f51ee42555d4437fd45ae5c2e59d6672b52047d192
templeR0038.png 218669 0a7f2ab0a1417e5bca7a83998623e62347709a31b961a98709a748261d45a614
templeR0039.png 204527 7232a5acc6930fd5c9edd2e8fd3ae91c3a3bf004334b950de44fab0eb5f7e0e4
templeR0040.png 218941 e57bc17cffb7f92761ad9055b3bc06d6babd729229165992cc26a0f3fe4e01e8
templeR0041.png 265566 dfcfc91feff2878d37be3327e1e1a528d1c7d8c94e76e8b27ede5fda22f4a26d
templeR0042.png 280356 8a2451cedda6d8d26ca1e0f737e842f4bba3bb47ceb5127bf282f85a18c3ad0d
templeR0043.png 282297 7e313eece7c32133a3e5fc60b45f65fbee38f8297f47cb2e4706d99904f626bc
templeR0044.png 279800 3351b7e3dd3b195c19f60a1256049c58dc88099d57d3426728769a1eddd955e2
templeR0045.png 268847 672e53eb1bd31ed4e2167437dfee55d4c4213edcc42a8f89bda6f48a54581567
templeR0046.png 258375 6a4efc5c8353db82122b8e57687528c087346ed4e07f046d6fc8256dd9eacf6c
templeR0047.png 249977 ddbee9b07fe1cd29217dc6e3dcb9914e1b29532c0080392c5898f98001e21970
templeR_ang.txt 1747 90516612d6f5d6b00d483d9f43db0929b8b93289f9ccc9aaf9704df6d120b313
templeR_par.txt 17227 ad81a6208dd931997ea885859b711608614f11a6aa54c432b621cf3007fb09f6
""",
    "chessboard": """
calibration.yml 213 0c9ef645721f31e412b20b583f766c192f32ab5225585cc61e6036383ca4fcf4
left01.jpg 27908 9621899098adffa1440c8264606bb7be535ccfd9ad126ae8e0bd9b0c5a5b8676
left02.jpg 28611 052e700bbcc865c112958ec2ea105cb1bce4deca50ac8d6efae13adca9df7a2c
left03.jpg 29553 c85b9426c3d8fcf161e1e727356105091009c3fd0b1b1a65bc2da91fea2724d2
left04.jpg 25150 b490599dccfbfe5eb56d33363415b02227a9548ab8c9b8e7b05d3580e97266d9
left05.jpg 28743 40bab8934fa76f82ec614a7fd0e6ebb4d9f74391d5e8b0c6f2f0ed6080c6c4de
left06.jpg 28530 1cb164db61b3bd52f58a7e9340bb27c5e0278895bc80b6f292fba5cf9bccc4a1
left07.jpg 29864 d2211fe9f971646b6ff88ed93a4f0d3f443741eb2894095cba15caade7c8c6e4
left08.jpg 28689 f7a0737894812a28243af5b409c5689f4fadfe7610958b8ca5fc79aec2f2cd1b
left09.jpg 27244 753939bc62d093c001d9118e989bef2b887f1b2f9ac03603df915a8b85aa81d3
left11.jpg 27749 e736ace3d515c94c547009c3c10d818c81506ed7059cb31123749b9cc3f94ee8
left12.jpg 25603 04bdd78b3b507fe0551aa7062a3ffd94846a147ee2bea7fb38082c720bdbe231
left13.jpg 28129 2637fb6dd5e557f4fadb06b353a453eb0b9223f4671f6f572f815302bc4a70b3
left14.jpg 27875 d4c032971dd7b859f9d6aed5090c9888bd8039b82e0604bee5bfe05444fce834
left_intrinsics.yml 3187 93a35a94eaaa63afba5128292cf2800fce3e783eba12a69e3d3731360d594684
right01.jpg 27072 94a160342fade4d0c4d2e94b8cb6c1e144a6e7682389d2991257e3a28625cb2d
right02.jpg 27263 f7819b2fcc45fdeff0cefd666a1f8bd2a5828c4d34367d7b6b6691f442bf1c42
right03.jpg 28652 43a3cea1907be641268ea18478362ab6c459424a9d8b7265eb5fb2264fcfb894
right04.jpg 24314 d5874ff3d948dbb673beb035dd70aef5e517119ff626ecdfd612fdd6a1eec32e
right05.jpg 26307 9382a24af5a21a9e3ec477bd4f74011e4bb10b0cdbc7e0de3ae60b75e95d650b
right06.jpg 27849 874b60edc8a53da477c6ee393184a1aafdc83ceaedcb4d0535f7c482d1c80e76
right07.jpg 28426 446093eead30c8cb1e51c8d01d322907760a3a57876596a81af6bf0795e9be67
right08.jpg 28292 5f1be870c8709fd5fc4dd578103b320018aabb4e18b8e8edaba9afbdd4d0b8f4
right09.jpg 25915 de28e9f146f4b7de78b0e39be6682997a7428f8ec5ef4efc753415d4ff8d9d76
right11.jpg 25725 2695e8f8e94eaef0bcfe56818090dada6dc76f53e30b77b97bea3a91080949db
right12.jpg 24796 07489b6a334fae390954bbbddedf03a0556163e5e364820838e881ebd3f33e0d
right13.jpg 27379 a576cc5e69668d65dd926366d103c4c77377e0cd71403e4e0fc278e335ed953c
right14.jpg 25748 e98bbe907610e9499d704bd0fe68d4adc158b19346cbc32f4cfe8a0014b1bd62
stereo_calib.xml 433 585a31531d6624f34acfce2cc9ca0be4d46d30db061494c8ea189f7274b80391
""",
    "bal": """
problem-49-7776-pre.txt 1785529 96ca2845519d89d0727953d983427ab38a42c54991cd4d73e46a4221da3c61b4
""",
}

DATASETS = {ds.name: ds for ds in (
    DataSet(
        name="dino",
        title="Oxford VGG dinosaur turntable: BAdino2.mat (36 cameras, 676 points with noise-free and noisy tracks, "
              "4,983 real tracks) and the 36 images viff.000-035.png, 720x576",
        origin="https://www.robots.ox.ac.uk/~vgg/data/mview/",
        licence="none stated",
        citation="Visual Geometry Group, University of Oxford, multi-view data 'Dinosaur'; A. W. Fitzgibbon, "
                 "G. Cross, A. Zisserman, 'Automatic 3D model construction for turn-table sequences', SMILE 1998",
        sources=(),
        files=_parse(_TABLES["dino"]),
        note="no public download of these files is known: BAdino2.mat is a course's file (cameras, points and "
             "tracks of the VGG data) whose public origin we could not confirm, and the VGG page serves the images "
             "as PPM files, not these PNGs. Copy the folder from your course, or set $LABUTILS_DATA_URL to a "
             "server that holds <name>/<path>"),
    DataSet(
        name="fountain-P11",
        title="EPFL/Strecha fountain-P11: 11 images, 3072x2048, with K, R, C per image",
        origin="http://cvlabwww.epfl.ch/data/multiview/ (gone; it served PNGs)",
        licence="none stated",
        citation="C. Strecha, W. von Hansen, L. Van Gool, P. Fua, U. Thoennessen, 'On Benchmarking Camera "
                 "Calibration and Multi-View Stereo for High Resolution Imagery', CVPR 2008",
        sources=(Source("files", f"{_GITHUB}/openMVG/SfM_quality_evaluation/348a981ef51112e9848acfb20004f4ed6fbc6ce3"
                                 "/Benchmarking_Camera_Calibration_2008/fountain-P11", "mirror"),),
        files=_parse(_TABLES["fountain-P11"]),
        note="the openMVG benchmark's copy: images recompressed to quality-100 JPEG, cameras renamed .jpg.camera"),
    DataSet(
        name="templeRing",
        title="Middlebury multi-view stereo templeRing: 47 images, 640x480, with K, R, t per image",
        origin="https://vision.middlebury.edu/mview/data/",
        licence="none stated",
        citation="S. M. Seitz, B. Curless, J. Diebel, D. Scharstein, R. Szeliski, 'A Comparison and Evaluation of "
                 "Multi-View Stereo Reconstruction Algorithms', CVPR 2006",
        sources=(Source("zip", "https://vision.middlebury.edu/mview/data/data/templeRing.zip", "origin", "templeRing/"),
                 Source("files", f"{_GITHUB}/matteo-bruni/binocular-dense-stereo/"
                                 "073a9be9f22a1055f47396ed272a4de201e67f44/dataset_templeRing", "mirror")),
        files=_parse(_TABLES["templeRing"])),
    DataSet(
        name="chessboard",
        title="OpenCV sample chessboard views left01-14.jpg, right01-14.jpg (no 10), 640x480, 9x6 inner corners",
        origin="https://github.com/opencv/opencv/tree/4.6.0/samples/data",
        licence="Apache-2.0 (OpenCV; older parts BSD-3-Clause)",
        citation="OpenCV, samples/data (the images of samples/cpp/stereo_calib.cpp)",
        sources=(Source("files", f"{_GITHUB}/opencv/opencv/4.6.0/samples/data", "origin"),),
        files=_parse(_TABLES["chessboard"])),
    DataSet(
        name="bal",
        title="Bundle Adjustment in the Large, ladybug problem-49-7776-pre.txt: 49 cameras, 7,776 points, "
              "31,843 observations",
        origin="https://grail.cs.washington.edu/projects/bal/",
        licence="none stated",
        citation="S. Agarwal, N. Snavely, S. M. Seitz, R. Szeliski, 'Bundle Adjustment in the Large', ECCV 2010",
        sources=(Source("bz2", "https://grail.cs.washington.edu/projects/bal/data/ladybug", "origin"),
                 Source("files", f"{_GITHUB}/AndreiBarsan/numerics-from-scratch/"
                                 "637eec6fcd8694a9338c6ba55a1d26cdaa0c389b/data/small", "mirror")),
        files=_parse(_TABLES["bal"])),
)}


# ---------------------------------------------------------------------------------------------------------------
# checking what is there
# ---------------------------------------------------------------------------------------------------------------
def file_ok(path, entry: DataFile) -> bool:
    """True if ``path`` is a file with the size and sha256 of ``entry``."""
    path = Path(path)
    return path.is_file() and path.stat().st_size == entry.size and pooch.file_hash(str(path)) == entry.sha256


@dataclass
class SetStatus:
    """Where a data set is on the data path and whether it is complete.

    Attributes
    ----------
    state : {'present', 'incomplete', 'missing'}
    folder : Path or None
        The set's folder that was judged (the first complete one, else the first that exists).
    missing, corrupt : list of str
        Paths (inside the set) absent, or present with the wrong size or sha256.
    """

    state: str
    folder: Path = None
    missing: list = field(default_factory=list)
    corrupt: list = field(default_factory=list)


def status(name: str, dirs=None) -> SetStatus:
    """Check a data set on the data path (every file's size and sha256).

    Parameters
    ----------
    name : str
        A key of :data:`DATASETS`.
    dirs : list of Path, optional
        The folders to search; default :func:`labutils.data.data_dirs`.

    Returns
    -------
    SetStatus

    >>> status("bal", dirs=[]).state
    'missing'
    """
    ds = dataset(name)
    first = None
    for d in data_dirs() if dirs is None else dirs:
        folder = Path(d) / ds.name
        if not folder.is_dir():
            continue
        st = SetStatus("present", folder)
        for f in ds.files:
            p = folder / f.path
            if not p.exists():
                st.missing.append(f.path)
            elif not file_ok(p, f):
                st.corrupt.append(f.path)
        if not st.missing and not st.corrupt:
            return st
        st.state = "incomplete"
        first = first or st
    return first or SetStatus("missing")


def dataset(name):
    try:
        return DATASETS[name]
    except KeyError:
        raise KeyError(f"unknown data set {name!r}; choose from {', '.join(DATASETS)}") from None
