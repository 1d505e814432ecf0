//! Opening real drivers from rig entries: addresses with and without a port.

use softtouch_drivers::open;

#[tokio::test]
async fn addresses_take_an_optional_port() {
    assert_eq!(
        open::resolve("127.0.0.1", 49152)
            .await
            .expect("host")
            .port(),
        49152
    );
    assert_eq!(
        open::resolve("127.0.0.1:5000", 49152)
            .await
            .expect("host:port")
            .port(),
        5000
    );
    assert_eq!(open::resolve("::1", 49152).await.expect("v6").port(), 49152);
    assert_eq!(
        open::resolve("[::1]:7", 49152)
            .await
            .expect("v6 port")
            .port(),
        7
    );
    let c = open::netft_config("127.0.0.1:6000", 1000.0, None, None)
        .await
        .expect("config");
    assert_eq!(
        c.scaling,
        softtouch_drivers::netft::Scaling::CalibrationRequest(([127, 0, 0, 1], 5999).into())
    );
}
