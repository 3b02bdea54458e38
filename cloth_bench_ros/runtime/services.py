"""
rclpy's services, clients and futures for the embedded runtime.

A service type has a Request and a Response message (`<pkg>/srv/<Srv>_Request`, `_Response`).
A client's call_async() returns a Future that the executor completes when the reply arrives; the
service's callback runs in the executor as rclpy runs it, `callback(request, Response())`, and
must return the response. The transports carry them: in one process through the context's queue,
over DDS as rmw_cyclonedds does (runtime/dds/services.py). The service types carried are the
parameter services' (rcl_interfaces/srv), which every node offers (runtime/parameter_service.py).
"""

from __future__ import annotations

import itertools
import time
from typing import Any, Callable

from cloth_bench_ros.runtime.messages import message_class
from cloth_bench_ros.runtime.qos import QoSProfile


def service_class(srv_type: str) -> type:
    """Return a class like rclpy's generated service types: `.Request` and `.Response` classes."""
    package, _, name = srv_type.split('/')
    return type(
        name,
        (),
        {
            '__srvtype__': srv_type,
            'Request': message_class(srv_type + '_Request'),
            'Response': message_class(srv_type + '_Response'),
        },
    )


DescribeParameters = service_class('rcl_interfaces/srv/DescribeParameters')
GetParameters = service_class('rcl_interfaces/srv/GetParameters')
GetParameterTypes = service_class('rcl_interfaces/srv/GetParameterTypes')
ListParameters = service_class('rcl_interfaces/srv/ListParameters')
SetParameters = service_class('rcl_interfaces/srv/SetParameters')
SetParametersAtomically = service_class('rcl_interfaces/srv/SetParametersAtomically')


def services_qos() -> QoSProfile:
    """rmw_qos_profile_services_default: reliable, volatile, keep last 10."""
    return QoSProfile(depth=10)


def parameters_qos() -> QoSProfile:
    """rmw_qos_profile_parameters: reliable, volatile, keep last 1000 (the parameter services)."""
    return QoSProfile(depth=1000)


class Future:
    """rclpy.task.Future: the outcome of a call, set once by the executor."""

    def __init__(self) -> None:
        self._done = False
        self._cancelled = False
        self._result: Any = None
        self._exception: BaseException | None = None
        self._callbacks: list[Callable[['Future'], None]] = []

    def done(self) -> bool:
        return self._done

    def cancelled(self) -> bool:
        return self._cancelled

    def cancel(self) -> None:
        if not self._done:
            self._cancelled = True
            self._finish()

    def result(self) -> Any:
        """Return what the call returned (None until done); raise what it raised."""
        if self._exception is not None:
            raise self._exception
        return self._result

    def exception(self) -> BaseException | None:
        return self._exception

    def set_result(self, result: Any) -> None:
        self._result = result
        self._finish()

    def set_exception(self, exception: BaseException) -> None:
        self._exception = exception
        self._finish()

    def add_done_callback(self, callback: Callable[['Future'], None]) -> None:
        if self._done:
            callback(self)
        else:
            self._callbacks.append(callback)

    def _finish(self) -> None:
        self._done = True
        for callback in self._callbacks:
            callback(self)
        self._callbacks.clear()


class Service:
    """A node's service: the executor hands it each request, it sends the callback's response."""

    def __init__(
        self,
        node: Any,
        srv_type: Any,
        srv_name: str,
        service_name: str,
        callback: Callable,
        qos: QoSProfile,
    ) -> None:
        self.node, self.srv_type, self.qos, self.callback = node, srv_type, qos, callback
        self.srv_name = srv_name  # as given (rclpy); service_name is resolved and remapped
        self.service_name = service_name
        self._queued = self._dropped = 0  # the context's queue counts them as for subscriptions

    def handle(self, item: tuple[Any, Any]) -> None:
        """Run the service callback on a queued (request id, request) and send its response."""
        request_id, request = item
        response = self.callback(request, self.srv_type.Response())
        if not isinstance(response, self.srv_type.Response):
            raise TypeError(  # rclpy: the callback must return the response it was given
                f'Expected {self.srv_type.Response.__name__}, got {type(response).__name__}'
            )
        self.node.context.transport.send_response(self, request_id, response)

    def destroy(self) -> None:
        self.node.context.transport.remove_service(self)


class Client:
    """A node's client of a service: call_async() sends, the executor completes the future."""

    _sequence = itertools.count(1)  # request sequence numbers, unique in the process (as rmw)

    def __init__(
        self, node: Any, srv_type: Any, srv_name: str, service_name: str, qos: QoSProfile
    ) -> None:
        self.node, self.srv_type, self.qos = node, srv_type, qos
        self.srv_name, self.service_name = srv_name, service_name
        self._pending: dict[int, Future] = {}
        self._queued = self._dropped = 0

    def call_async(self, request: Any) -> Future:
        """Send a request; return a Future completed when its response arrives."""
        if not isinstance(request, self.srv_type.Request):
            raise TypeError(
                f'Expected {self.srv_type.Request.__name__}, got {type(request).__name__}'
            )
        future = Future()
        sequence = next(self._sequence)
        self._pending[sequence] = future
        self.node.context.transport.send_request(self, sequence, request)
        return future

    def handle(self, item: tuple[int, Any]) -> None:
        """Complete the future of a queued (sequence number, response); drop unknown ones."""
        sequence, response = item
        future = self._pending.pop(sequence, None)
        if future is not None and not future.cancelled():
            future.set_result(response)

    def remove_pending_request(self, future: Future) -> None:
        for sequence, pending in list(self._pending.items()):
            if pending is future:
                del self._pending[sequence]

    def service_is_ready(self) -> bool:
        return bool(self.node.context.transport.service_is_ready(self))

    def wait_for_service(self, timeout_sec: float | None = None) -> bool:
        """Wait until a server of the service is matched (True), or timeout_sec passed (False)."""
        end = None if timeout_sec is None else time.monotonic() + timeout_sec
        while not self.service_is_ready():
            if end is not None and time.monotonic() >= end:
                return False
            time.sleep(0.01)
        return True

    def destroy(self) -> None:
        self.node.context.transport.remove_client(self)
